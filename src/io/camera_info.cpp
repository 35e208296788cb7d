#include "mc_flow/io/camera_info.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"

namespace mc_flow {
namespace io {
namespace {

std::string trim(const std::string& s) {
  const std::size_t b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const std::size_t e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

bool parseNumber(const std::string& text, double& value) {
  const std::string t = trim(text);
  if (t.empty()) return false;
  char* end = nullptr;
  value = std::strtod(t.c_str(), &end);
  return end && *end == '\0';
}

struct YamlLine {
  int indent = 0;
  std::string key;    // empty for "- item" lines
  std::string value;  // text after "key:" or "- "
};

// A line-oriented reading of the YAML subset camera_info files use: "key: value", "key: [a, b, ...]"
// (possibly continued on following lines), nested mappings by indentation and "- item" block sequences.
std::vector<YamlLine> yamlLines(const std::string& text) {
  std::vector<YamlLine> lines;
  std::istringstream in(text);
  std::string raw;
  while (std::getline(in, raw)) {
    const std::size_t hash = raw.find('#');
    if (hash != std::string::npos) raw = raw.substr(0, hash);
    if (trim(raw).empty() || trim(raw) == "---" || raw.rfind("%YAML", 0) == 0) continue;
    YamlLine line;
    line.indent = int(raw.find_first_not_of(' '));
    const std::string body = trim(raw);
    // Continuation of an open flow sequence from the previous line.
    if (!lines.empty()) {
      std::string& prev = lines.back().value;
      if (prev.find('[') != std::string::npos && prev.find(']') == std::string::npos) {
        prev += " " + body;
        continue;
      }
    }
    if (body.rfind("- ", 0) == 0 || body == "-") {
      line.value = trim(body.substr(1));
    } else {
      const std::size_t colon = body.find(':');
      if (colon == std::string::npos) continue;
      line.key = trim(body.substr(0, colon));
      line.value = trim(body.substr(colon + 1));
    }
    lines.push_back(line);
  }
  return lines;
}

// Values of key `key` at any depth whose parent chain ends with `parent` ("" = any parent).
bool findNumbers(const std::vector<YamlLine>& lines, const std::string& parent, const std::string& key,
                 std::vector<double>& numbers) {
  for (std::size_t i = 0; i < lines.size(); ++i) {
    if (lines[i].key != key) continue;
    if (!parent.empty()) {
      // The parent is the nearest earlier line with smaller indentation.
      bool parent_ok = false;
      for (std::size_t j = i; j-- > 0;) {
        if (lines[j].indent < lines[i].indent && !lines[j].key.empty()) {
          parent_ok = lines[j].key == parent;
          break;
        }
      }
      if (!parent_ok) continue;
    }
    numbers.clear();
    std::string value = lines[i].value;
    if (!value.empty() && value.front() == '[') {
      const std::size_t close = value.find(']');
      std::stringstream items(value.substr(1, close == std::string::npos ? std::string::npos : close - 1));
      std::string item;
      while (std::getline(items, item, ',')) {
        double v;
        if (trim(item).empty()) continue;
        if (!parseNumber(item, v)) return false;
        numbers.push_back(v);
      }
      return true;
    }
    if (value.empty()) {  // block sequence: following "- x" lines
      for (std::size_t j = i + 1; j < lines.size() && lines[j].key.empty(); ++j) {
        double v;
        if (!parseNumber(lines[j].value, v)) return false;
        numbers.push_back(v);
      }
      return true;
    }
    double v;
    if (!parseNumber(value, v)) return false;
    numbers.push_back(v);
    return true;
  }
  return false;
}

int findInt(const std::vector<YamlLine>& lines, const std::string& key) {
  std::vector<double> v;
  if (findNumbers(lines, "", key, v) && v.size() == 1) return int(v[0]);
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
                       trim(item) + "')");
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
  const std::vector<YamlLine> lines = yamlLines(text);
  CameraInfo info;
  std::vector<double> k, p;
  const bool have_k = findNumbers(lines, "", "K", k) || findNumbers(lines, "", "k", k) ||
                      findNumbers(lines, "camera_matrix", "data", k);
  const bool have_p = findNumbers(lines, "", "P", p) || findNumbers(lines, "", "p", p) ||
                      findNumbers(lines, "projection_matrix", "data", p);
  const bool k_usable = have_k && k.size() == 9 && k[0] != 0.0 && k[4] != 0.0;
  const bool p_usable = have_p && p.size() == 12 && p[0] != 0.0 && p[5] != 0.0;
  if (k_usable) {
    info.intrinsics = {k[0], k[4], k[2], k[5]};
  } else if (p_usable) {
    info.intrinsics = {p[0], p[5], p[2], p[6]};
  } else if (have_k || have_p) {
    throw InputError(what + ": K (9 numbers) and P (12 numbers) are both missing, malformed or zero");
  } else {
    throw InputError(what + ": no K or P matrix found (expected 'K: [...]' or 'camera_matrix: data: [...]')");
  }
  info.width = findInt(lines, "width");
  if (!info.width) info.width = findInt(lines, "image_width");
  info.height = findInt(lines, "height");
  if (!info.height) info.height = findInt(lines, "image_height");
  checkIntrinsics(info.intrinsics, what);
  return info;
}

CameraInfo loadCameraInfo(const std::string& path) {
  if (!fileExists(path)) throw InputError("camera info '" + path + "': file does not exist");
  return parseCameraInfoYaml(readTextFile(path), "camera info '" + path + "'");
}

void saveCameraInfo(const std::string& path, const CameraInfo& info) {
  const Intrinsics& K = info.intrinsics;
  char buffer[1024];
  std::snprintf(buffer, sizeof(buffer),
                "# sensor_msgs/CameraInfo of the mc_flow synthetic camera (rectified, no distortion)\n"
                "height: %d\nwidth: %d\ndistortion_model: \"plumb_bob\"\n"
                "D: [0.0, 0.0, 0.0, 0.0, 0.0]\n"
                "K: [%.17g, 0.0, %.17g, 0.0, %.17g, %.17g, 0.0, 0.0, 1.0]\n"
                "R: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n"
                "P: [%.17g, 0.0, %.17g, 0.0, 0.0, %.17g, %.17g, 0.0, 0.0, 0.0, 1.0, 0.0]\n"
                "binning_x: 0\nbinning_y: 0\n",
                info.height, info.width, K.fx, K.cx, K.fy, K.cy, K.fx, K.cx, K.fy, K.cy);
  writeTextFile(path, buffer);
}

}  // namespace io
}  // namespace mc_flow
