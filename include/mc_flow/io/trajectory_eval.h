/**
 * @file trajectory_eval.h
 * @brief A camera trajectory scored against ground truth as the TUM RGB-D benchmark defines it (Sturm et al., IROS
 * 2012): the absolute trajectory error (ATE: RMSE of the positions after the rigid alignment that minimises it) and the
 * relative pose error (RPE: the error of the motion over a fixed interval, per frame and per second).
 */
#pragma once

#include <opencv2/core.hpp>

#include "mc_flow/eval/metrics.h"

namespace mc_flow {
namespace io {

// The ATE/RPE maths is shared with the synthetic benchmarks, which run without OpenCV (mc_flow/eval/metrics.h).
using mc_flow::evaluateTrajectory;
using mc_flow::StampedPoses;
using mc_flow::TrajectoryErrors;

/// @brief Both paths from above (x and z of the camera's optical frame, y pointing down: the floor plane of a camera
/// looking ahead), ground truth in grey, the aligned estimate in orange, with a 10 cm scale bar.
cv::Mat trajectoryPlot(const TrajectoryErrors& errors, int size_px = 600);

}  // namespace io
}  // namespace mc_flow
