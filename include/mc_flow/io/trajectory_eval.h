/**
 * @file trajectory_eval.h
 * @brief A camera trajectory scored against ground truth as the TUM RGB-D benchmark defines it (Sturm et al., IROS
 * 2012): the absolute trajectory error (ATE: RMSE of the positions after the rigid alignment that minimises it) and the
 * relative pose error (RPE: the error of the motion over a fixed interval, per frame and per second).
 */
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace mc_flow {
namespace io {

using StampedPoses = std::vector<std::pair<double, Eigen::Matrix4d>>;

struct TrajectoryErrors {
  int matched = 0;                 ///< estimated poses with a ground-truth pose within max_difference
  double ate_rmse_m = 0;           ///< after the rigid alignment (no scale)
  double rpe_frame_trans_m = 0;    ///< RMSE of consecutive matched frames' relative motion: translation [m]
  double rpe_frame_rot_deg = 0;    ///< ... rotation [deg]
  int rpe_frame_pairs = 0;
  double rpe_second_trans_m = 0;   ///< over about one second (the first frame at least 1 s later) [m]
  double rpe_second_rot_deg = 0;   ///< [deg]
  int rpe_second_pairs = 0;
  Eigen::Matrix4d alignment = Eigen::Matrix4d::Identity();  ///< ground truth <- estimate
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> positions;  ///< (ground truth, aligned estimate) per match
};

/// @brief Matches each estimated pose (stamp + time_offset) to the nearest ground-truth stamp within max_difference
/// [s] and scores the matches. Throws InputError when fewer than 3 poses match (naming the counts).
TrajectoryErrors evaluateTrajectory(const StampedPoses& ground_truth, const StampedPoses& estimate,
                                    double max_difference, double time_offset);

/// @brief Both paths from above (x and z of the camera's optical frame, y pointing down: the floor plane of a camera
/// looking ahead), ground truth in grey, the aligned estimate in orange, with a 10 cm scale bar.
cv::Mat trajectoryPlot(const TrajectoryErrors& errors, int size_px = 600);

}  // namespace io
}  // namespace mc_flow
