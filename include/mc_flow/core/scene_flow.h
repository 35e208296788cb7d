/**
 * @file scene_flow.h
 * @brief The interpolated motion per pixel: warped points, scene flow and optical flow.
 */
#pragma once

#include <vector>

#include "mc_flow/core/image.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

/// @brief P2(x) = exp(xi_bar(x)) P(x): 3 channels, NaN where the point is invalid. xi_bar(x) = sum_i w_i(x) xi_i
/// over the motion labels, w = u renormalised without the outlier label; a pixel with (almost) no motion-label
/// mass moves with its largest motion label.
ImageF warpPoints(const ImageF& points, const SoftLabels& u, const std::vector<Vector6d>& twists);

/// @brief The motions as scene_flow_pixel.h's per-pixel warp reads them: per twist 18 doubles, the twist, then rows
/// 0..2 of its exp (se3Exp). `out` holds 18 * twists.size() doubles.
void packMotions(const std::vector<Vector6d>& twists, double* out);

/// @brief Scene flow P2 - P (3 channels, m) and optical flow pi(P2) - x (2 channels, px); NaN where invalid.
void sceneAndOpticalFlow(const ImageF& points, const ImageF& warped_points, const Intrinsics& K, ImageF& scene_flow,
                         ImageF& optical_flow);

}  // namespace mc_flow
