/**
 * @file motion_estimation.h
 * @brief Motion step: the twists of all labels solved jointly by Cauchy IRLS under the
 * motion-interpolation model (eq. 2), coarse to fine.
 */
#pragma once

#include <cmath>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

struct MotionLevelStats {
  int level = 0;
  int iterations = 0;
  int pixels_used = 0;
  double cost_before = 0;  ///< robust cost (normalised Cauchy) at the first iteration
  double cost_after = 0;   ///< at the last iteration
};

/// @brief IRLS at one level. `labels` has the level's size; `occluded` (may be null) excludes pixels.
/// `twists` holds one twist per motion label (labels.count - 1) and is updated in place.
MotionLevelStats estimateMotionsAtLevel(const PyramidLevel& frame1, const PyramidLevel& frame2, const SoftLabels& labels,
                                        const ImageU8* occluded, std::vector<Vector6d>& twists, const Config& config);

/// @brief Robust per-pixel data cost of one residual pair (normalised Cauchy, used by both steps):
/// ln(1 + (rI/cI)^2) + alpha * ln(1 + (rZ/cZ)^2).
inline double cauchyCost(double r, double c) { const double q = r / c; return std::log1p(q * q); }

}  // namespace mc_flow
