// Sequences on disk: TUM RGB-D lists, numbered frame folders, trajectories.csv and the ids-over-time picture.
#include "mc_flow/io/sequence_io.h"

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/visualization.h"

namespace fs = std::filesystem;

namespace mc_flow {
namespace io {

namespace {

struct StampedFile {
  double stamp = 0;
  std::string file;
};

// "stamp file [stamp file]" lines; '#' comments and blank lines are skipped.
std::vector<std::vector<std::string>> readColumns(const std::string& path, std::size_t columns) {
  const std::string text = readTextFile(path);
  std::vector<std::vector<std::string>> rows;
  std::istringstream lines(text);
  std::string line;
  int number = 0;
  while (std::getline(lines, line)) {
    ++number;
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream fields(line);
    std::vector<std::string> row;
    std::string field;
    while (fields >> field) row.push_back(field);
    if (row.size() < columns)
      throw InputError("'" + path + "' line " + std::to_string(number) + ": expected " + std::to_string(columns) +
                       " columns, got '" + line + "'");
    rows.push_back(row);
  }
  return rows;
}

double stampOf(const std::string& text, const std::string& path) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (!end || *end != '\0' || !std::isfinite(v)) throw InputError("'" + path + "': '" + text + "' is not a time stamp");
  return v;
}

std::vector<StampedFile> readList(const std::string& path) {
  std::vector<StampedFile> out;
  for (const auto& row : readColumns(path, 2)) out.push_back({stampOf(row[0], path), row[1]});
  return out;
}

std::string inDir(const std::string& dir, const std::string& name) { return (fs::path(dir) / name).string(); }

std::vector<std::string> imagesIn(const std::string& dir) {
  std::vector<std::string> out;
  if (!fs::is_directory(dir)) return out;
  for (const auto& entry : fs::directory_iterator(dir)) {
    std::string ext = entry.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (entry.is_regular_file() && (ext == ".png" || ext == ".jpg" || ext == ".pgm" || ext == ".ppm" || ext == ".pfm" ||
                                    ext == ".exr" || ext == ".tif" || ext == ".tiff"))
      out.push_back(entry.path().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

std::vector<SequenceFrameFiles> listTumSequence(const std::string& dir, double max_difference) {
  if (!fs::is_directory(dir)) throw InputError("TUM sequence '" + dir + "': not a directory");
  std::vector<SequenceFrameFiles> frames;
  for (const char* name : {"associations.txt", "associate.txt"}) {
    const std::string path = inDir(dir, name);
    if (!fs::exists(path)) continue;
    for (const auto& row : readColumns(path, 4))
      frames.push_back({stampOf(row[0], path), inDir(dir, row[1]), inDir(dir, row[3])});
    if (frames.empty()) throw InputError("TUM sequence '" + dir + "': '" + path + "' lists no frame");
    return frames;
  }
  const std::string rgb_list = inDir(dir, "rgb.txt"), depth_list = inDir(dir, "depth.txt");
  if (!fs::exists(rgb_list) || !fs::exists(depth_list))
    throw InputError("TUM sequence '" + dir + "': needs rgb.txt and depth.txt (or associations.txt)");
  const std::vector<StampedFile> rgb = readList(rgb_list);
  std::vector<StampedFile> depth = readList(depth_list);
  std::sort(depth.begin(), depth.end(), [](const auto& a, const auto& b) { return a.stamp < b.stamp; });
  for (const StampedFile& r : rgb) {
    const auto after = std::lower_bound(depth.begin(), depth.end(), r.stamp,
                                        [](const StampedFile& d, double s) { return d.stamp < s; });
    const StampedFile* best = nullptr;
    if (after != depth.end()) best = &*after;
    if (after != depth.begin() && (!best || r.stamp - std::prev(after)->stamp < best->stamp - r.stamp))
      best = &*std::prev(after);
    if (best && std::abs(best->stamp - r.stamp) <= max_difference)
      frames.push_back({r.stamp, inDir(dir, r.file), inDir(dir, best->file)});
  }
  if (frames.empty())
    throw InputError("TUM sequence '" + dir + "': no RGB frame has a depth frame within " +
                     std::to_string(max_difference) + " s");
  return frames;
}

std::vector<SequenceFrameFiles> listNumberedFrames(const std::string& dir, double fps) {
  if (!(fps > 0) || !std::isfinite(fps)) throw InputError("frame rate " + std::to_string(fps) + " must be > 0");
  const std::vector<std::string> rgb = imagesIn(inDir(dir, "rgb")), depth = imagesIn(inDir(dir, "depth"));
  if (rgb.empty() || depth.empty())
    throw InputError("frame folder '" + dir + "': needs images in rgb/ and depth/ (found " +
                     std::to_string(rgb.size()) + " and " + std::to_string(depth.size()) + ")");
  if (rgb.size() != depth.size())
    throw InputError("frame folder '" + dir + "': " + std::to_string(rgb.size()) + " images in rgb/ but " +
                     std::to_string(depth.size()) + " in depth/");
  std::vector<SequenceFrameFiles> frames;
  for (std::size_t i = 0; i < rgb.size(); ++i) frames.push_back({double(i) / fps, rgb[i], depth[i]});
  return frames;
}

std::string trajectoryCsvHeader() {
  return "pair,stamp,id,vx,vy,vz,wx,wy,wz,support,world,moving,world_vx,world_vy,world_vz,world_wx,world_wy,world_wz\n";
}

std::string trajectoryCsvRows(long pair, double stamp, const Result& result, const std::vector<WorldVelocity>* world) {
  if (world && world->size() != result.segments.size())
    throw InputError("trajectory rows: " + std::to_string(world->size()) + " world velocities for " +
                     std::to_string(result.segments.size()) + " segments");
  std::ostringstream out;
  out.precision(9);
  for (std::size_t i = 0; i < result.segments.size(); ++i) {
    const Segment& s = result.segments[i];
    out << pair << ',' << std::fixed << stamp << std::defaultfloat << ',' << s.id;
    for (int k = 0; k < 6; ++k) out << ',' << s.twist[k];
    out << ',' << s.support;
    if (world) {
      const bool is_world = result.world.contains(s.id);
      const WorldVelocity& v = (*world)[i];
      out << ',' << (is_world ? 1 : 0) << ',' << (v.moving ? 1 : 0);
      for (int k = 0; k < 3; ++k) out << ',' << v.linear[k];
      for (int k = 0; k < 3; ++k) out << ',' << v.angular[k];
    } else {
      out << ",,,,,,,,";
    }
    out << '\n';
  }
  return out.str();
}

std::string odometryCsvHeader() {
  std::string header = "pair,stamp_first,stamp_second,vx,vy,vz,wx,wy,wz";
  for (int r = 0; r < 6; ++r)
    for (int c = r; c < 6; ++c) header += ",c" + std::to_string(r + 1) + std::to_string(c + 1);
  return header + "\n";
}

std::string odometryCsvRow(long pair, const OdometryStep& step) {
  std::ostringstream out;
  out.precision(9);
  out << pair << ',' << std::fixed << step.first << ',' << step.second << std::defaultfloat;
  for (int k = 0; k < 6; ++k) out << ',' << step.twist[k];
  out.precision(12);
  for (int r = 0; r < 6; ++r)
    for (int c = r; c < 6; ++c) out << ',' << step.covariance(r, c);
  out << '\n';
  return out.str();
}

std::vector<OdometryStep> readOdometryCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError("odometry '" + path + "': cannot be opened");
  std::vector<OdometryStep> steps;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos || (number == 1 && line.rfind("pair", 0) == 0))
      continue;  // blank, or the header
    std::vector<double> v;
    std::istringstream fields(line);
    for (std::string field; std::getline(fields, field, ',');) {
      char* end = nullptr;
      const double x = std::strtod(field.c_str(), &end);
      const bool only_space_after =
          field.find_first_not_of(" \t\r", std::size_t(end - field.c_str())) == std::string::npos;
      if (end == field.c_str() || !only_space_after || !std::isfinite(x)) {
        v.clear();
        break;
      }
      v.push_back(x);
    }
    if (v.size() != 30)
      throw InputError("odometry '" + path + "', line " + std::to_string(number) +
                       ": expected 30 numbers (pair, two stamps, the twist, 21 covariance values), got '" + line + "'");
    OdometryStep step;
    step.first = v[1];
    step.second = v[2];
    for (int k = 0; k < 6; ++k) step.twist[k] = v[3 + std::size_t(k)];
    std::size_t k = 9;
    for (int r = 0; r < 6; ++r)
      for (int c = r; c < 6; ++c, ++k) step.covariance(r, c) = step.covariance(c, r) = v[k];
    steps.push_back(step);
  }
  return steps;
}

std::vector<std::pair<double, Eigen::Matrix4d>> readTumTrajectory(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError("trajectory '" + path + "': cannot be opened");
  std::vector<std::pair<double, Eigen::Matrix4d>> out;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty() || line[0] == '#' || line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream fields(line);
    double v[8];
    for (double& x : v)
      if (!(fields >> x) || !std::isfinite(x))
        throw InputError("trajectory '" + path + "', line " + std::to_string(number) +
                         ": expected 'stamp tx ty tz qx qy qz qw', got '" + line + "'");
    const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    if (std::fabs(q.norm() - 1.0) > 1e-2)
      throw InputError("trajectory '" + path + "', line " + std::to_string(number) + ": quaternion of norm " +
                       std::to_string(q.norm()) + ", expected 1");
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    T.topLeftCorner<3, 3>() = q.normalized().toRotationMatrix();
    T.topRightCorner<3, 1>() = Eigen::Vector3d(v[1], v[2], v[3]);
    out.emplace_back(v[0], T);
  }
  return out;
}

cv::Mat idsOverTimeImage(const std::vector<std::vector<std::pair<int, double>>>& ids_per_pair) {
  std::set<int> all;
  double largest = 0;
  for (const auto& pair : ids_per_pair)
    for (const auto& [id, support] : pair) {
      all.insert(id);
      largest = std::max(largest, support);
    }
  const int cell = 8, columns = std::max<int>(1, int(ids_per_pair.size())), rows = std::max<int>(1, int(all.size()));
  cv::Mat image(rows * cell, columns * cell, CV_8UC3, cv::Scalar(40, 40, 40));
  std::map<int, int> row_of;
  for (const int id : all) row_of.emplace(id, int(row_of.size()));
  for (int p = 0; p < int(ids_per_pair.size()); ++p)
    for (const auto& [id, support] : ids_per_pair[std::size_t(p)]) {
      const double shade = largest > 0 ? 0.35 + 0.65 * std::sqrt(support / largest) : 1.0;
      const cv::Vec3b c = segmentColor(id);
      const cv::Scalar colour(c[0] * shade, c[1] * shade, c[2] * shade);
      cv::rectangle(image, cv::Rect(p * cell, row_of.at(id) * cell, cell - 1, cell - 1), colour, cv::FILLED);
    }
  return image;
}

}  // namespace io
}  // namespace mc_flow
