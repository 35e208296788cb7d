// The trajectory plot of `mcflow eval-traj` (its ATE and RPE: mc_flow/eval/metrics.cpp).
#include "mc_flow/io/trajectory_eval.h"

#include <algorithm>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace mc_flow {
namespace io {

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
    return cv::Point(int(0.075 * size_px + (p.x() - min_x) * scale),
                     int(size_px - 0.075 * size_px - (p.z() - min_z) * scale));
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
  cv::putText(image, "ground truth", {10, 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(120, 120, 120), 1,
              cv::LINE_AA);
  cv::putText(image, "estimate (aligned)", {10, 40}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 140, 255), 1,
              cv::LINE_AA);
  return image;
}

}  // namespace io
}  // namespace mc_flow
