#include "mc_flow/io/camera_info.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "mc_flow/core/error.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/text.h"

namespace mc_flow {
namespace io {
namespace {

bool parseNumber(const std::string& text, double& value) {
  const std::string t = trimWhitespace(text);
  if (t.empty()) return false;
  char* end = nullptr;
  value = std::strtod(t.c_str(), &end);
  return end && *end == '\0';
}

// yaml-cpp marks count lines and columns from 0; people count from 1.
std::string position(const YAML::Mark& mark) {
  return "line " + std::to_string(mark.line + 1) + ", column " + std::to_string(mark.column + 1);
}

// A camera matrix as the file gives it: a plain number sequence (message form, `K: [...]`) or a
// {rows, cols, data: [...]} mapping (camera_calibration_parsers form, `camera_matrix:`).
struct MatrixEntry {
  bool present = false;
  std::string where;  // the key and its position, for messages
  std::vector<double> values;
  std::string problem;  // why the values are unusable ("" when they are usable)
};

MatrixEntry readMatrix(const YAML::Node& root, const std::vector<std::string>& names, std::size_t expected) {
  MatrixEntry m;
  for (const std::string& name : names) {
    const YAML::Node node = root[name];
    if (!node.IsDefined() || node.IsNull()) continue;
    m.present = true;
    m.where = "'" + name + "' (" + position(node.Mark()) + ")";
    const std::string& where = m.where;
    // Copy-construct: assigning to a YAML::Node would overwrite the node it refers to inside the document.
    const YAML::Node data = node.IsMap() ? node["data"] : node;
    if (node.IsMap()) {
      if (!data.IsDefined()) {
        m.problem = where + " has no 'data' sequence";
        return m;
      }
      const YAML::Node rows = node["rows"], cols = node["cols"];
      const std::string shape = expected == 9 ? "3x3" : "3x4";
      if (rows.IsScalar() && cols.IsScalar() && rows.Scalar() + "x" + cols.Scalar() != shape) {
        m.problem = where + " is " + rows.Scalar() + "x" + cols.Scalar() + ", expected " + shape;
        return m;
      }
    }
    if (!data.IsSequence()) {
      m.problem = where + " is not a sequence of numbers";
      return m;
    }
    for (std::size_t i = 0; i < data.size(); ++i) {
      try {
        m.values.push_back(data[i].as<double>());
      } catch (const YAML::Exception&) {
        m.problem = where + " item " + std::to_string(i) + " ('" + (data[i].IsScalar() ? data[i].Scalar() : "...") +
                    "') is not a number";
        return m;
      }
    }
    if (m.values.size() != expected)
      m.problem = where + " has " + std::to_string(m.values.size()) + " numbers, expected " + std::to_string(expected);
    return m;
  }
  return m;
}

// Image width/height under the first of `names` present; 0 when none is.
int readSize(const YAML::Node& root, const std::vector<std::string>& names, const std::string& what) {
  for (const std::string& name : names) {
    const YAML::Node node = root[name];
    if (!node.IsDefined() || node.IsNull()) continue;
    int value = -1;
    try {
      value = node.as<int>();
    } catch (const YAML::Exception&) {
    }
    if (value < 0)
      throw InputError(what + ", " + position(node.Mark()) + ": '" + name + "' = '" +
                       (node.IsScalar() ? node.Scalar() : "...") + "' is not an image size in pixels");
    return value;
  }
  return 0;
}

}  // namespace

void checkIntrinsics(const Intrinsics& K, const std::string& what) {
  const double values[4] = {K.fx, K.fy, K.cx, K.cy};
  const char* names[4] = {"fx", "fy", "cx", "cy"};
  for (int i = 0; i < 4; ++i) {
    if (!std::isfinite(values[i]))
      throw InputError(what + ": " + names[i] + " is not finite (" + std::to_string(values[i]) + ")");
    if (i < 2 && !(values[i] > 0))
      throw InputError(what + ": " + names[i] + " must be > 0 pixels, got " + std::to_string(values[i]));
  }
}

Intrinsics parseIntrinsics(const std::string& text) {
  const std::string what = "intrinsics '" + text + "'";
  std::vector<double> values;
  std::stringstream items(text);
  std::string item;
  while (std::getline(items, item, ',')) {
    double v;
    if (!parseNumber(item, v))
      throw InputError(what + ": malformed; expected four comma-separated numbers FX,FY,CX,CY (bad item '" +
                       trimWhitespace(item) + "')");
    values.push_back(v);
  }
  if (values.size() != 4)
    throw InputError(what + ": malformed; expected four comma-separated numbers FX,FY,CX,CY, got " +
                     std::to_string(values.size()));
  Intrinsics K{values[0], values[1], values[2], values[3]};
  checkIntrinsics(K, what);
  return K;
}

std::string formatIntrinsics(const Intrinsics& K) {
  char buffer[160];
  std::snprintf(buffer, sizeof(buffer), "%.17g,%.17g,%.17g,%.17g", K.fx, K.fy, K.cx, K.cy);
  return buffer;
}

CameraInfo parseCameraInfoYaml(const std::string& text, const std::string& what) {
  YAML::Node root;
  try {
    root = YAML::Load(text);  // the first document: `rostopic echo -n 1` output and calibration files alike
  } catch (const YAML::ParserException& e) {
    throw InputError(what + ", " + position(e.mark) + ": " + e.msg);
  }
  if (!root.IsMap())
    throw InputError(what + ": expected a YAML mapping with a K or camera_matrix entry (no K or P matrix found)");
  // ROS 1 messages spell the matrices K/P, ROS 2 k/p, calibration files camera_matrix/projection_matrix.
  const MatrixEntry k = readMatrix(root, {"K", "k", "camera_matrix"}, 9);
  const MatrixEntry p = readMatrix(root, {"P", "p", "projection_matrix"}, 12);
  const bool k_usable = k.present && k.problem.empty() && k.values[0] != 0.0 && k.values[4] != 0.0;
  const bool p_usable = p.present && p.problem.empty() && p.values[0] != 0.0 && p.values[5] != 0.0;
  CameraInfo info;
  if (k_usable) {
    info.intrinsics = {k.values[0], k.values[4], k.values[2], k.values[5]};
  } else if (p_usable) {
    info.intrinsics = {p.values[0], p.values[5], p.values[2], p.values[6]};
  } else if (k.present || p.present) {
    auto why = [](const MatrixEntry& m, const std::string& name) {
      return !m.present ? name + " is missing" : !m.problem.empty() ? m.problem : m.where + " has zero focal lengths";
    };
    throw InputError(what + ": neither K (9 numbers) nor P (12 numbers) is usable: " + why(k, "K") + "; " +
                     why(p, "P"));
  } else {
    throw InputError(what + ": no K or P matrix found (expected 'K: [...]' or 'camera_matrix: {data: [...]}')");
  }
  info.width = readSize(root, {"width", "image_width"}, what);
  info.height = readSize(root, {"height", "image_height"}, what);
  checkIntrinsics(info.intrinsics, what);
  return info;
}

CameraInfo loadCameraInfo(const std::string& path) {
  if (!fileExists(path)) throw InputError("camera info '" + path + "': file does not exist");
  return parseCameraInfoYaml(readTextFile(path), "camera info '" + path + "'");
}

void saveCameraInfo(const std::string& path, const CameraInfo& info) {
  const Intrinsics& K = info.intrinsics;
  const std::vector<double> distortion(5, 0.0);
  const std::vector<double> camera = {K.fx, 0.0, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0};
  const std::vector<double> rotation = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  const std::vector<double> projection = {K.fx, 0.0, K.cx, 0.0, 0.0, K.fy, K.cy, 0.0, 0.0, 0.0, 1.0, 0.0};
  YAML::Emitter out;
  out.SetDoublePrecision(17);  // enough digits to parse back exactly
  out << YAML::Comment("sensor_msgs/CameraInfo of the mc_flow synthetic camera (rectified, no distortion)");
  out << YAML::BeginMap;
  out << YAML::Key << "height" << YAML::Value << info.height;
  out << YAML::Key << "width" << YAML::Value << info.width;
  out << YAML::Key << "distortion_model" << YAML::Value << YAML::DoubleQuoted << "plumb_bob";
  out << YAML::Key << "D" << YAML::Value << YAML::Flow << distortion;
  out << YAML::Key << "K" << YAML::Value << YAML::Flow << camera;
  out << YAML::Key << "R" << YAML::Value << YAML::Flow << rotation;
  out << YAML::Key << "P" << YAML::Value << YAML::Flow << projection;
  out << YAML::Key << "binning_x" << YAML::Value << 0;
  out << YAML::Key << "binning_y" << YAML::Value << 0;
  out << YAML::EndMap;
  if (!out.good()) throw FileError("camera info '" + path + "': cannot format: " + out.GetLastError());
  writeTextFile(path, std::string(out.c_str()) + "\n");
}

}  // namespace io
}  // namespace mc_flow
