// The odometry benchmark on real frames with moving objects composited in (issue 28), and OpenCV's rgbd odometry
// as the library baseline. Built only where OpenCV's contrib rgbd module is installed (CMakeLists.txt).
//
//   mcflow_bench_odometry composite --tum DIR --intrinsics FX,FY,CX,CY --out OUT [--boxes 2] [--seed 1]
//       [--offset -0.015]
//     A copy of the TUM RGB-D sequence DIR in OUT (the same layout: rgb/, depth/, rgb.txt, depth.txt,
//     associations.txt, groundtruth.txt) with textured boxes moving in the world frame, ray-cast into each frame at
//     that frame's ground-truth camera pose (groundtruth.txt at the colour stamp + offset) and z-tested against the
//     real depth. Box i is placed in front of the camera at frame (i + 1/2) N / boxes, not all at the first frame:
//     fr1/rpy pans ~100 deg in 1.3 s, and boxes placed at frame 0 had left the view by frame 20. The real images
//     are motion-blurred in the fast turns; the boxes are not. OUT/box_N.txt hold the boxes' world-from-box poses per
//     frame (TUM format); OUT/mask/ the box pixels of each frame (PNG, 255 = a box, named as its colour image);
//     OUT/composite.txt says how they were made.
//   mcflow_bench_odometry moving-iou --composited DIR --run RUN
//     Scores run-seq's moving.png of each pair (RUN/pair_NNNN) against DIR/mask at the pair's first frame (its
//     report.json's inputs.rgb1), sampled at the moving mask's resolution: the IoU of all pairs' pixels together, its
//     median per pair, the share of the box pixels flagged (recall) and of the other pixels flagged (the static scene
//     called moving).
//   mcflow_bench_odometry opencv --tum DIR --intrinsics FX,FY,CX,CY --out TRAJ [--method rgbd|icp|rgbdicp]
//     Frame-to-frame cv::rgbd::RgbdOdometry / ICPOdometry / RgbdICPOdometry with OpenCV's defaults, chained into a
//     TUM trajectory (colour stamps; the camera's optical frame in the first frame's). A pair that fails holds
//     the pose and is counted.
//
// scripts/bench_odometry.sh runs both against mc_flow and prints the table.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/core/image.h"
#include "mc_flow/io/camera_info.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/result_io.h"
#include "mc_flow/io/sequence_io.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/eval/synthetic_scene.h"

using namespace mc_flow;
namespace fs = std::filesystem;

namespace {

constexpr double kTumDepthScale = 5000.0;  // units per metre in TUM depth PNGs

double parseNumber(const std::string& name, const std::string& text) {
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
  }
  if (used != text.size() || !std::isfinite(value))
    throw CommandLineError("--" + name + ": '" + text + "' is not a number");
  return value;
}

// ---------------------------------------------------------------- ground truth

/// World-from-camera at `stamp`: translation linear, rotation slerped between the two bracketing mocap poses.
Eigen::Matrix4d interpolatePose(const std::vector<std::pair<double, Eigen::Matrix4d>>& poses, double stamp,
                                const std::string& path) {
  const auto after =
      std::lower_bound(poses.begin(), poses.end(), stamp, [](const auto& p, double s) { return p.first < s; });
  if (after == poses.end() || (after == poses.begin() && after->first > stamp)) {
    char text[160];
    std::snprintf(text, sizeof(text), "'%s' has no pose around %.6f (its poses span %.6f..%.6f)", path.c_str(), stamp,
                  poses.front().first, poses.back().first);
    throw InputError(text);
  }
  if (after->first == stamp) return after->second;
  const auto before = std::prev(after);
  const double a = (stamp - before->first) / (after->first - before->first);
  const Eigen::Quaterniond q0(before->second.topLeftCorner<3, 3>()), q1(after->second.topLeftCorner<3, 3>());
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = q0.slerp(a, q1).normalized().toRotationMatrix();
  T.topRightCorner<3, 1>() = (1 - a) * before->second.topRightCorner<3, 1>() + a * after->second.topRightCorner<3, 1>();
  return T;
}

// ---------------------------------------------------------------- composite

/// A textured box moving in the world at constant velocity: centre c0 + v t, orientation exp([w] t) R0 (w in the
/// world frame, about the centre), t in seconds since the first frame.
struct Box {
  Eigen::Vector3d half;  // [m]
  Eigen::Vector3d c0, v, w;
  Eigen::Matrix3d R0;
  Eigen::Vector3d tint;  // BGR gains in (0, 1]
  std::uint32_t texture_seed = 0;

  Eigen::Matrix4d worldFromBox(double t) const {
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(w.norm() * t, w.normalized()).toRotationMatrix() * R0;
    T.topRightCorner<3, 1>() = c0 + v * t;
    return T;
  }
};

std::uint32_t hash3(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  std::uint32_t h = a * 0x8da6b343u ^ b * 0xd8163841u ^ c * 0xcb1ab31fu;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  h ^= h >> 15;
  return h;
}

/// Grey level of the box's surface at face coordinates (a, b) [m]: 4 cm cells of random level (strong gradients
/// at every cell edge, at every pyramid level mc_flow and OpenCV use) with a dark line through every third cell.
double boxTexture(const Box& box, int face, double a, double b) {
  constexpr double kCell = 0.04;
  const int i = int(std::floor(a / kCell)), j = int(std::floor(b / kCell));
  const std::uint32_t h =
      hash3(std::uint32_t(i + 1000), std::uint32_t(j + 1000), box.texture_seed + std::uint32_t(face));
  double level = 30.0 + 210.0 * double(h & 0xffu) / 255.0;
  const double fa = a / kCell - i, fb = b / kCell - j;
  if ((h >> 8) % 3 == 0 && std::abs(fa - fb) < 0.12) level = 15.0;
  return level;
}

/// Where a box is placed: in front of the camera at one frame of the sequence (its anchor).
struct Anchor {
  double t = 0;  // [s] since the first frame
  Eigen::Matrix4d world_from_camera;
  double scene_depth = 0;  // [m] median real depth of the central third of the image
};

/// Box i is centred on the view of anchor i, nearer than most of the real scene there (so that the z-test keeps
/// it largely visible), and moves across that view at constant world velocity. The anchors are spread over the
/// sequence because the camera may turn far more than its field of view (fr1/rpy pans ~100 deg in 1.3 s): boxes
/// placed at the first frame alone would leave the view within a third of the sequence.
std::vector<Box> makeBoxes(const std::vector<Anchor>& anchors, std::uint32_t seed) {
  std::mt19937 rng(seed);
  auto uniform = [&rng](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  std::vector<Box> boxes;
  for (const Anchor& anchor : anchors) {
    const Eigen::Matrix3d R = anchor.world_from_camera.topLeftCorner<3, 3>();
    const Eigen::Vector3d t = anchor.world_from_camera.topRightCorner<3, 1>();
    Box box;
    box.half = Eigen::Vector3d(uniform(0.35, 0.5), uniform(0.35, 0.5), uniform(0.35, 0.5)) / 2;
    // Camera frame of the anchor: x right, y down, z forward. Mostly sideways, a little up/down and in depth.
    // Some boxes reach behind nearer real surfaces, which the z-test must cut away.
    const double depth = std::clamp(uniform(0.7, 0.95) * anchor.scene_depth, 0.9, 1.8);
    const double heading = uniform(-0.6, 0.6);  // [rad] off the horizontal
    const double direction = uniform(0, 1) < 0.5 ? -1.0 : 1.0;
    const Eigen::Vector3d velocity_c =
        uniform(0.3, 0.5) *
        Eigen::Vector3d(direction * std::cos(heading), std::sin(heading), uniform(-0.3, 0.3)).normalized();
    const Eigen::Vector3d centre_c(uniform(-0.1, 0.1), uniform(-0.1, 0.1), depth);
    box.v = R * velocity_c;
    box.c0 = R * centre_c + t - box.v * anchor.t;
    box.w = Eigen::Vector3d(uniform(-1, 1), uniform(-1, 1), uniform(-1, 1)).normalized() * uniform(0.5, 1.0);
    box.R0 = Eigen::Quaterniond(uniform(-1, 1), uniform(-1, 1), uniform(-1, 1), uniform(-1, 1))
                 .normalized()
                 .toRotationMatrix();
    box.tint = Eigen::Vector3d(uniform(0.5, 1.0), uniform(0.5, 1.0), uniform(0.5, 1.0));
    box.texture_seed = std::uint32_t(rng());
    boxes.push_back(box);
  }
  return boxes;
}

/// Median of the valid depth [m] in the central third of a 16-bit TUM depth image (0 when none is valid).
double centralDepth(const cv::Mat& depth) {
  std::vector<std::uint16_t> values;
  for (int v = depth.rows / 3; v < 2 * depth.rows / 3; ++v)
    for (int u = depth.cols / 3; u < 2 * depth.cols / 3; ++u)
      if (depth.at<std::uint16_t>(v, u) > 0) values.push_back(depth.at<std::uint16_t>(v, u));
  if (values.empty()) return 0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2] / kTumDepthScale;
}

/// The TUM file-name convention "STAMP.png": the depth image's own stamp, or `fallback` for other names.
double stampFromName(const std::string& path, double fallback) {
  const std::string stem = fs::path(path).stem().string();
  char* end = nullptr;
  const double value = std::strtod(stem.c_str(), &end);
  return end && *end == '\0' && !stem.empty() ? value : fallback;
}

int cmdComposite(const CommandLine& line) {
  const std::string dir = line.text("tum", ""), out = line.text("out", "");
  if (dir.empty() || out.empty() || !line.has("intrinsics"))
    throw CommandLineError("composite needs --tum DIR, --intrinsics FX,FY,CX,CY and --out OUT");
  const Intrinsics K = io::parseIntrinsics(line.text("intrinsics", ""));
  const int box_count = line.integer("boxes", 2, 0, 16);
  const int seed = line.integer("seed", 1, 0, std::numeric_limits<int>::max());
  const double offset = parseNumber("offset", line.text("offset", "-0.015"));

  const std::vector<io::SequenceFrameFiles> frames = io::listTumSequence(dir);
  const std::string gt_path = (fs::path(dir) / "groundtruth.txt").string();
  auto gt = io::readTumTrajectory(gt_path);
  if (gt.size() < 2) throw InputError("'" + gt_path + "' holds fewer than 2 poses");
  std::sort(gt.begin(), gt.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

  io::createOutputDirectory(out);
  fs::create_directories(fs::path(out) / "rgb");
  fs::create_directories(fs::path(out) / "depth");
  fs::create_directories(fs::path(out) / "mask");
  fs::copy_file(gt_path, fs::path(out) / "groundtruth.txt", fs::copy_options::overwrite_existing);

  const double t0 = frames.front().stamp;
  std::vector<Anchor> anchors;
  for (int b = 0; b < box_count; ++b) {
    const io::SequenceFrameFiles& frame = frames[std::size_t((b + 0.5) * double(frames.size()) / box_count)];
    const cv::Mat depth = cv::imread(frame.depth, cv::IMREAD_ANYDEPTH);
    if (depth.empty() || depth.type() != CV_16UC1) throw InputError("'" + frame.depth + "': not a 16-bit depth PNG");
    anchors.push_back({frame.stamp - t0, interpolatePose(gt, frame.stamp + offset, gt_path), centralDepth(depth)});
  }
  const std::vector<Box> boxes = makeBoxes(anchors, std::uint32_t(seed));
  std::vector<std::string> box_poses(boxes.size(),
                                     "# world-from-box at the colour stamps (the box's centre; "
                                     "axes along its edges)\n# timestamp tx ty tz qx qy qz qw\n");
  std::string rgb_list =
      "# colour images with moving boxes composited in (mcflow_bench_odometry composite)\n"
      "# timestamp filename\n";
  std::string depth_list = "# depth maps with moving boxes composited in\n# timestamp filename\n", associations;
  std::vector<double> coverage, in_view_fraction;  // per frame: box pixels after and before the z-test
  for (std::size_t f = 0; f < frames.size(); ++f) {
    const io::SequenceFrameFiles& frame = frames[f];
    cv::Mat colour = cv::imread(frame.rgb, cv::IMREAD_COLOR);
    cv::Mat depth = cv::imread(frame.depth, cv::IMREAD_ANYDEPTH);
    if (colour.empty()) throw InputError("'" + frame.rgb + "': cannot read the colour image");
    if (depth.empty() || depth.type() != CV_16UC1) throw InputError("'" + frame.depth + "': not a 16-bit depth PNG");
    if (colour.size() != depth.size()) throw InputError("'" + frame.rgb + "' and '" + frame.depth + "' differ in size");

    // The boxes are rendered where the camera was when the colour image was exposed; the real depth lags that
    // by a further ~15 ms (README of the excerpt), which leaves a few pixels of mismatch at occluding edges.
    const double t = frame.stamp - t0;
    const Eigen::Matrix4d world_from_camera = interpolatePose(gt, frame.stamp + offset, gt_path);
    std::vector<Eigen::Matrix3d> R_bc(boxes.size());
    std::vector<Eigen::Vector3d> o_b(boxes.size());
    for (std::size_t b = 0; b < boxes.size(); ++b) {
      const Eigen::Matrix4d world_from_box = boxes[b].worldFromBox(t);
      const Eigen::Matrix4d box_from_camera = world_from_box.inverse() * world_from_camera;
      R_bc[b] = box_from_camera.topLeftCorner<3, 3>();
      o_b[b] = box_from_camera.topRightCorner<3, 1>();
      box_poses[b] += io::tumTrajectoryLine(frame.stamp, world_from_box);
    }
    long replaced = 0, in_view = 0;
    cv::Mat box_mask(colour.size(), CV_8UC1, cv::Scalar(0));
    for (int v = 0; v < colour.rows; ++v) {
      auto* bgr = colour.ptr<cv::Vec3b>(v);
      auto* on_box = box_mask.ptr<std::uint8_t>(v);
      auto* z_real = depth.ptr<std::uint16_t>(v);
      for (int u = 0; u < colour.cols; ++u) {
        // The ray's parameter is the camera's z, as the direction has z = 1 in the camera frame.
        const Eigen::Vector3d ray((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0);
        double z_best = std::numeric_limits<double>::infinity();
        int box_best = -1, face_best = 0;
        Eigen::Vector3d hit_best;
        for (std::size_t b = 0; b < boxes.size(); ++b) {
          const Eigen::Vector3d d = R_bc[b] * ray;
          int face = 0;
          double z = 0;
          if (intersectBox(o_b[b], d, boxes[b].half, z, face) && z < z_best) {
            z_best = z;
            box_best = int(b);
            face_best = face;
            hit_best = o_b[b] + z * d;
          }
        }
        if (box_best < 0) continue;
        ++in_view;
        if (z_real[u] != 0 && z_best * kTumDepthScale >= z_real[u]) continue;  // the real scene is nearer
        const int axis = face_best / 2;
        const double level = boxTexture(boxes[box_best], face_best, hit_best[(axis + 1) % 3], hit_best[(axis + 2) % 3]);
        for (int c = 0; c < 3; ++c) bgr[u][c] = cv::saturate_cast<std::uint8_t>(level * boxes[box_best].tint[c]);
        z_real[u] = std::uint16_t(std::min(65535.0, std::round(z_best * kTumDepthScale)));
        on_box[u] = 255;
        ++replaced;
      }
    }
    coverage.push_back(double(replaced) / double(colour.total()));
    in_view_fraction.push_back(double(in_view) / double(colour.total()));

    const std::string rgb_name = "rgb/" + fs::path(frame.rgb).filename().string();
    const std::string depth_name = "depth/" + fs::path(frame.depth).filename().string();
    io::writeImage((fs::path(out) / rgb_name).string(), colour);
    io::writeImage((fs::path(out) / depth_name).string(), depth);
    io::writeImage((fs::path(out) / "mask" / fs::path(frame.rgb).filename()).string(), box_mask);
    char stamps[64];
    std::snprintf(stamps, sizeof(stamps), "%.6f", frame.stamp);
    const std::string rgb_stamp = stamps;
    std::snprintf(stamps, sizeof(stamps), "%.6f", stampFromName(frame.depth, frame.stamp));
    const std::string depth_stamp = stamps;
    rgb_list += rgb_stamp + " " + rgb_name + "\n";
    depth_list += depth_stamp + " " + depth_name + "\n";
    associations += rgb_stamp + " " + rgb_name + " " + depth_stamp + " " + depth_name + "\n";
    std::fprintf(stderr, "\rmcflow_bench_odometry: composited %zu/%zu frames", f + 1, frames.size());
  }
  std::fprintf(stderr, "\n");
  io::writeTextFile((fs::path(out) / "rgb.txt").string(), rgb_list);
  io::writeTextFile((fs::path(out) / "depth.txt").string(), depth_list);
  io::writeTextFile((fs::path(out) / "associations.txt").string(), associations);

  std::ostringstream about;
  about << "Composited by mcflow_bench_odometry composite from " << dir << " (" << frames.size() << " frames), seed "
        << seed << ", " << boxes.size() << " box(es).\n"
        << "Camera: world-from-camera from groundtruth.txt at the colour stamp " << (offset < 0 ? "- " : "+ ")
        << std::abs(offset) << " s (interpolated); intrinsics " << K.fx << "," << K.fy << "," << K.cx << "," << K.cy
        << ".\nBoxes move in the world frame (groundtruth.txt's), t = colour stamp - " << std::fixed << t0
        << std::defaultfloat << " s; a box pixel replaces colour and depth where it is nearer than the real depth "
        << "or the real depth is missing. Poses per frame: box_N.txt; the box pixels of each frame: mask/.\n";
  for (std::size_t b = 0; b < boxes.size(); ++b) {
    const Box& box = boxes[b];
    about << "box " << b << ": anchored at t=" << anchors[b].t << " s (scene depth " << anchors[b].scene_depth
          << " m), size " << 2 * box.half.transpose() << " m, centre at t=0 " << box.c0.transpose() << " m, velocity "
          << box.v.transpose() << " m/s (" << box.v.norm() << "), angular velocity " << box.w.transpose() << " rad/s ("
          << box.w.norm() << ")\n";
    io::writeTextFile((fs::path(out) / ("box_" + std::to_string(b) + ".txt")).string(), box_poses[b]);
  }
  const double mean_coverage = std::accumulate(coverage.begin(), coverage.end(), 0.0) / double(coverage.size());
  const double mean_in_view =
      std::accumulate(in_view_fraction.begin(), in_view_fraction.end(), 0.0) / double(in_view_fraction.size());
  char summary[200];
  std::snprintf(summary, sizeof(summary),
                "box pixels per frame: mean %.1f %%, min %.1f %%, max %.1f %% (%.1f %% of those in view hidden by "
                "the real scene)\n",
                100 * mean_coverage, 100 * *std::min_element(coverage.begin(), coverage.end()),
                100 * *std::max_element(coverage.begin(), coverage.end()),
                mean_in_view > 0 ? 100 * (1 - mean_coverage / mean_in_view) : 0.0);
  about << summary;
  io::writeTextFile((fs::path(out) / "composite.txt").string(), about.str());
  std::printf("wrote %s: %zu frames, %zu box(es); %s", out.c_str(), frames.size(), boxes.size(), summary);
  return 0;
}

// ---------------------------------------------------------------- moving mask against the boxes

int cmdMovingIou(const CommandLine& line) {
  const std::string dir = line.text("composited", ""), run = line.text("run", "");
  if (dir.empty() || run.empty()) throw CommandLineError("moving-iou needs --composited DIR and --run RUN");
  if (!fs::is_directory(run)) throw InputError("--run: '" + run + "' is not a directory (mcflow run-seq's --out)");
  if (!fs::is_directory(fs::path(dir) / "mask"))
    throw InputError("'" + dir + "' has no mask/ (made by a composite before masks, or not a composited sequence)");
  // run-seq numbers its pairs as it solves them (a skipped frame or a reset shifts the numbers): each pair's frame 1
  // is the rgb1 of its report.json, and its box mask is mask/ under that file's name.
  std::vector<fs::path> pair_dirs;
  for (const fs::directory_entry& entry : fs::directory_iterator(run))
    if (entry.is_directory() && entry.path().filename().string().rfind("pair_", 0) == 0) pair_dirs.push_back(entry);
  std::sort(pair_dirs.begin(), pair_dirs.end());
  long both = 0, either = 0, truth = 0, flagged_static = 0, static_pixels = 0;
  std::vector<double> per_pair;
  std::size_t pairs = 0;
  for (const fs::path& pair_dir : pair_dirs) {
    const fs::path moving_path = pair_dir / "moving.png", report_path = pair_dir / "report.json";
    if (!fs::exists(moving_path))  // run-seq writes one for every solved pair
      throw InputError("'" + pair_dir.string() + "' has no moving.png (not written by mcflow run-seq?)");
    const nlohmann::json report = io::readJsonFile(report_path.string());
    if (!report.contains("inputs") || !report["inputs"].contains("rgb1") || !report["inputs"]["rgb1"].is_string())
      throw InputError("'" + report_path.string() + "' names no inputs.rgb1 (not written by mcflow run-seq?)");
    const fs::path truth_path =
        fs::path(dir) / "mask" / fs::path(report["inputs"]["rgb1"].get<std::string>()).filename();
    const cv::Mat moving = cv::imread(moving_path.string(), cv::IMREAD_GRAYSCALE);
    const cv::Mat boxes = cv::imread(truth_path.string(), cv::IMREAD_GRAYSCALE);
    if (moving.empty()) throw InputError("'" + moving_path.string() + "': cannot read the moving mask");
    if (boxes.empty())
      throw InputError("'" + truth_path.string() + "': cannot read the box mask of " + pair_dir.string() +
                       "'s first frame (was the run made on this composited sequence?)");
    if (boxes.cols % moving.cols != 0 || boxes.rows % moving.rows != 0 ||
        boxes.cols / moving.cols != boxes.rows / moving.rows)
      throw InputError("'" + moving_path.string() + "' (" + std::to_string(moving.cols) + "x" +
                       std::to_string(moving.rows) + ") is not the box mask's size (" + std::to_string(boxes.cols) +
                       "x" + std::to_string(boxes.rows) + ") divided by a whole number");
    const int step = boxes.cols / moving.cols;
    long pair_both = 0, pair_either = 0;
    for (int y = 0; y < moving.rows; ++y)
      for (int x = 0; x < moving.cols; ++x) {
        // The box mask at the centre of the block the moving mask's pixel stands for.
        const bool box = boxes.at<std::uint8_t>(y * step + step / 2, x * step + step / 2) != 0;
        const bool flagged = moving.at<std::uint8_t>(y, x) != 0;
        pair_both += box && flagged;
        pair_either += box || flagged;
        truth += box;
        static_pixels += !box;
        flagged_static += flagged && !box;
      }
    both += pair_both;
    either += pair_either;
    if (pair_either > 0) per_pair.push_back(double(pair_both) / double(pair_either));
    ++pairs;
  }
  if (pairs == 0) throw InputError("'" + run + "' holds no pair_NNNN/moving.png");
  std::sort(per_pair.begin(), per_pair.end());
  const std::size_t half = per_pair.size() / 2;
  const double median = per_pair.empty()           ? 1.0
                        : per_pair.size() % 2 == 1 ? per_pair[half]
                                                   : 0.5 * (per_pair[half - 1] + per_pair[half]);
  std::printf("pairs %zu\nmoving_iou %.4f\nmoving_iou_median %.4f\nbox_recall %.4f\nstatic_flagged %.4f\n", pairs,
              either > 0 ? double(both) / double(either) : 1.0, median, truth > 0 ? double(both) / double(truth) : 1.0,
              static_pixels > 0 ? double(flagged_static) / double(static_pixels) : 0.0);
  return 0;
}

// ---------------------------------------------------------------- OpenCV odometry

int cmdOpenCv(const CommandLine& line) {
  const std::string dir = line.text("tum", ""), out = line.text("out", "");
  if (dir.empty() || out.empty() || !line.has("intrinsics"))
    throw CommandLineError("opencv needs --tum DIR, --intrinsics FX,FY,CX,CY and --out TRAJ");
  const Intrinsics K = io::parseIntrinsics(line.text("intrinsics", ""));
  const std::string method = line.text("method", "rgbd");
  cv::Mat camera = (cv::Mat_<float>(3, 3) << float(K.fx), 0, float(K.cx), 0, float(K.fy), float(K.cy), 0, 0, 1);
  cv::Ptr<cv::rgbd::Odometry> odometry;
  if (method == "rgbd")
    odometry = cv::rgbd::RgbdOdometry::create(camera);
  else if (method == "icp")
    odometry = cv::rgbd::ICPOdometry::create(camera);
  else if (method == "rgbdicp")
    odometry = cv::rgbd::RgbdICPOdometry::create(camera);
  else
    throw CommandLineError("--method: '" + method + "' is none of rgbd, icp, rgbdicp");

  const std::vector<io::SequenceFrameFiles> frames = io::listTumSequence(dir);
  // OpenCV's rgbd odometry wants 8-bit grey and float depth in metres with NaN where there is no measurement.
  auto load = [](const io::SequenceFrameFiles& frame, cv::Mat& grey, cv::Mat& depth) {
    const cv::Mat colour = cv::imread(frame.rgb, cv::IMREAD_GRAYSCALE);
    const cv::Mat raw = cv::imread(frame.depth, cv::IMREAD_ANYDEPTH);
    if (colour.empty()) throw InputError("'" + frame.rgb + "': cannot read the colour image");
    if (raw.empty() || raw.type() != CV_16UC1) throw InputError("'" + frame.depth + "': not a 16-bit depth PNG");
    if (colour.size() != raw.size()) throw InputError("'" + frame.rgb + "' and '" + frame.depth + "' differ in size");
    grey = colour;
    raw.convertTo(depth, CV_32FC1, 1.0 / kTumDepthScale);
    depth.setTo(std::numeric_limits<float>::quiet_NaN(), raw == 0);
  };

  std::string trajectory = "# mcflow_bench_odometry opencv --method " + method +
                           ": the colour camera's optical frame in the first frame's, frame to frame\n"
                           "# timestamp tx ty tz qx qy qz qw\n";
  Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();
  trajectory += io::tumTrajectoryLine(frames.front().stamp, pose);
  cv::Mat previous_grey, previous_depth;
  load(frames.front(), previous_grey, previous_depth);
  int failed = 0;
  double total_ms = 0;
  for (std::size_t f = 1; f < frames.size(); ++f) {
    cv::Mat grey, depth;
    load(frames[f], grey, depth);
    // Source = this frame, destination = the previous one: Rt maps this frame's points into the previous
    // frame's, i.e. it is previous-from-current, the factor that chains onto the pose (OpenCV's own sample).
    cv::Mat Rt;
    bool ok = false;
    const auto start = std::chrono::steady_clock::now();
    try {
      ok = odometry->compute(grey, depth, cv::Mat(), previous_grey, previous_depth, cv::Mat(), Rt);
    } catch (const cv::Exception& e) {
      std::fprintf(stderr, "mcflow_bench_odometry: pair %zu: %s\n", f - 1, e.what());
    }
    total_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (ok && Rt.rows == 4 && Rt.cols == 4) {
      Eigen::Matrix4d step;
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) step(r, c) = Rt.at<double>(r, c);
      pose = pose * step;
    } else {
      ++failed;  // the pose is held
    }
    trajectory += io::tumTrajectoryLine(frames[f].stamp, pose);
    previous_grey = grey;
    previous_depth = depth;
  }
  const fs::path parent = fs::path(out).parent_path();
  if (!parent.empty()) io::createOutputDirectory(parent.string());
  io::writeTextFile(out, trajectory);
  std::printf("opencv %s: %zu pairs, %d failed (pose held), %.1f ms/pair; wrote %s\n", method.c_str(),
              frames.size() - 1, failed, total_ms / double(frames.size() - 1), out.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string usage =
      "usage: mcflow_bench_odometry composite --tum DIR --intrinsics FX,FY,CX,CY --out OUT [--boxes 2] [--seed 1] "
      "[--offset -0.015]\n"
      "       mcflow_bench_odometry opencv --tum DIR --intrinsics FX,FY,CX,CY --out TRAJ [--method rgbd|icp|rgbdicp]\n"
      "       mcflow_bench_odometry moving-iou --composited DIR --run RUN\n";
  const std::string command = argc > 1 ? argv[1] : "";
  if (command != "composite" && command != "opencv" && command != "moving-iou") {
    std::fprintf(stderr, "%s", usage.c_str());
    return command == "--help" || command == "-h" ? 0 : 2;
  }
  std::vector<CommandLineOption> options;
  if (command != "moving-iou")
    options = {{"tum", true, "TUM RGB-D directory (rgb.txt, depth.txt, optional associations.txt; depth 5000 units/m)"},
               {"intrinsics", true, "FX,FY,CX,CY in pixels (TUM fr1: 517.3,516.5,318.6,255.3)"}};
  if (command == "moving-iou") {
    options.push_back({"composited", true, "a sequence made by composite (its mask/ holds the box pixels)"});
    options.push_back({"run", true, "mcflow run-seq's output directory on that sequence"});
  } else if (command == "composite") {
    options.push_back({"out", true, "output directory (created): the sequence with the boxes, in the TUM layout"});
    options.push_back({"boxes", true, "number of moving boxes (default 2)"});
    options.push_back({"seed", true, "seed of the boxes' sizes, poses, velocities and textures (default 1)"});
    options.push_back({"offset", true, "[s] ground truth sampled at colour stamp + offset (default -0.015)"});
  } else {
    options.push_back({"out", true, "trajectory file to write (TUM format)"});
    options.push_back({"method", true, "rgbd (RgbdOdometry) | icp (ICPOdometry) | rgbdicp (RgbdICPOdometry)"});
  }
  CommandLine line("mcflow_bench_odometry " + command, options);
  try {
    line.parse(argc - 1, argv + 1);
    if (line.helpRequested()) {
      std::printf("%s", line.usage().c_str());
      return 0;
    }
    if (command == "moving-iou") return cmdMovingIou(line);
    return command == "composite" ? cmdComposite(line) : cmdOpenCv(line);
  } catch (const CommandLineError& e) {
    std::fprintf(stderr, "mcflow_bench_odometry: %s\n%s", e.what(), line.usage().c_str());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench_odometry: %s\n", e.what());
    return 1;
  }
}
