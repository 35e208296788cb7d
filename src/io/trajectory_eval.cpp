// ATE and RPE as the TUM RGB-D benchmark defines them, for `mcflow eval-traj`.
#include "mc_flow/io/trajectory_eval.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "mc_flow/core/error.h"

namespace mc_flow {
namespace io {

namespace {

double rotationDeg(const Eigen::Matrix4d& T) {
  const double c = std::clamp((T.topLeftCorner<3, 3>().trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * 180.0 / M_PI;
}

Eigen::Matrix4d relative(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) { return a.inverse() * b; }

}  // namespace

TrajectoryErrors evaluateTrajectory(const StampedPoses& ground_truth, const StampedPoses& estimate,
                                    double max_difference, double time_offset) {
  if (!(max_difference >= 0)) throw InputError("max difference must be >= 0 s, got " + std::to_string(max_difference));
  StampedPoses gt = ground_truth;
  std::sort(gt.begin(), gt.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<std::pair<Eigen::Matrix4d, Eigen::Matrix4d>> matched;  // (ground truth, estimate)
  std::vector<double> stamps;
  StampedPoses est = estimate;  // in time order: the RPE pairs consecutive and one-second-apart poses
  std::stable_sort(est.begin(), est.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [stamp, pose] : est) {
    const double t = stamp + time_offset;
    auto it = std::lower_bound(gt.begin(), gt.end(), t, [](const auto& a, double v) { return a.first < v; });
    const auto* best = it != gt.end() ? &*it : nullptr;
    if (it != gt.begin() && (!best || t - std::prev(it)->first < best->first - t)) best = &*std::prev(it);
    if (!best || std::fabs(best->first - t) > max_difference) continue;
    matched.emplace_back(best->second, pose);
    stamps.push_back(stamp);
  }
  if (matched.size() < 3)
    throw InputError("trajectory evaluation: " + std::to_string(matched.size()) + " of " +
                     std::to_string(estimate.size()) + " estimated poses have a ground-truth pose within " +
                     std::to_string(max_difference) + " s (" + std::to_string(ground_truth.size()) +
                     " ground-truth poses); at least 3 are needed");
  TrajectoryErrors e;
  e.matched = int(matched.size());
  Eigen::Matrix3Xd from(3, e.matched), to(3, e.matched);
  for (int i = 0; i < e.matched; ++i) {
    from.col(i) = matched[std::size_t(i)].second.topRightCorner<3, 1>();
    to.col(i) = matched[std::size_t(i)].first.topRightCorner<3, 1>();
  }
  e.alignment = Eigen::umeyama(from, to, false);
  double sum = 0;
  for (int i = 0; i < e.matched; ++i) {
    const Eigen::Vector3d aligned = (e.alignment * from.col(i).homogeneous()).head<3>();
    sum += (aligned - to.col(i)).squaredNorm();
    e.positions.emplace_back(to.col(i), aligned);
  }
  e.ate_rmse_m = std::sqrt(sum / e.matched);
  // RPE over consecutive matched frames, and over about one second.
  double t_sum = 0, r_sum = 0, t_sum_s = 0, r_sum_s = 0;
  auto add = [&](std::size_t i, std::size_t j, double& ts, double& rs, int& count) {
    const Eigen::Matrix4d error = relative(relative(matched[i].first, matched[j].first), relative(matched[i].second, matched[j].second));
    ts += error.topRightCorner<3, 1>().squaredNorm();
    const double r = rotationDeg(error);
    rs += r * r;
    ++count;
  };
  for (std::size_t i = 0; i + 1 < matched.size(); ++i) add(i, i + 1, t_sum, r_sum, e.rpe_frame_pairs);
  for (std::size_t i = 0; i < matched.size(); ++i) {
    const auto j = std::lower_bound(stamps.begin() + long(i), stamps.end(), stamps[i] + 1.0);
    if (j == stamps.end()) break;
    add(i, std::size_t(j - stamps.begin()), t_sum_s, r_sum_s, e.rpe_second_pairs);
  }
  e.rpe_frame_trans_m = std::sqrt(t_sum / std::max(1, e.rpe_frame_pairs));
  e.rpe_frame_rot_deg = std::sqrt(r_sum / std::max(1, e.rpe_frame_pairs));
  if (e.rpe_second_pairs > 0) {
    e.rpe_second_trans_m = std::sqrt(t_sum_s / e.rpe_second_pairs);
    e.rpe_second_rot_deg = std::sqrt(r_sum_s / e.rpe_second_pairs);
  }
  return e;
}

cv::Mat trajectoryPlot(const TrajectoryErrors& errors, int size_px) {
  cv::Mat image(size_px, size_px, CV_8UC3, cv::Scalar(255, 255, 255));
  if (errors.positions.empty()) return image;
  double min_x = 1e300, max_x = -1e300, min_z = 1e300, max_z = -1e300;
  for (const auto& [g, a] : errors.positions)
    for (const Eigen::Vector3d& p : {g, a}) {
      min_x = std::min(min_x, p.x());
      max_x = std::max(max_x, p.x());
      min_z = std::min(min_z, p.z());
      max_z = std::max(max_z, p.z());
    }
  const double span = std::max({max_x - min_x, max_z - min_z, 0.1});
  const double scale = 0.85 * size_px / span;
  auto at = [&](const Eigen::Vector3d& p) {
    return cv::Point(int(0.075 * size_px + (p.x() - min_x) * scale), int(size_px - 0.075 * size_px - (p.z() - min_z) * scale));
  };
  std::vector<cv::Point> truth, estimate;
  for (const auto& [g, a] : errors.positions) {
    truth.push_back(at(g));
    estimate.push_back(at(a));
  }
  cv::polylines(image, truth, false, cv::Scalar(120, 120, 120), 2, cv::LINE_AA);
  cv::polylines(image, estimate, false, cv::Scalar(0, 140, 255), 2, cv::LINE_AA);
  const int bar = int(0.1 * scale);
  cv::line(image, {10, size_px - 10}, {10 + bar, size_px - 10}, cv::Scalar(0, 0, 0), 2);
  cv::putText(image, "10 cm", {12, size_px - 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  cv::putText(image, "ground truth", {10, 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(120, 120, 120), 1, cv::LINE_AA);
  cv::putText(image, "estimate (aligned)", {10, 40}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 140, 255), 1,
              cv::LINE_AA);
  return image;
}

}  // namespace io
}  // namespace mc_flow
