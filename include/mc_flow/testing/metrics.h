/**
 * @file metrics.h
 * @brief The paper's metrics (Tables 1-2) plus ground-truth comparisons for synthetic scenes.
 */
#pragma once

#include <cstddef>

#include "mc_flow/core/image.h"

namespace mc_flow {

struct FlowErrors {
  double epe = 0;        ///< mean end-point error [px]
  double aae_deg = 0;    ///< mean angular error [deg] (Barron et al., on (u, v, 1))
  std::size_t pixels = 0;
};

struct ResidualRmse {
  double photometric = 0;  ///< intensity in [0, 1]
  double geometric = 0;    ///< [m]
  std::size_t pixels = 0;
};

/// @brief EPE and AAE of optical flow over pixels where both are finite and `excluded` (may be null) is 0.
FlowErrors opticalFlowErrors(const ImageF& estimate, const ImageF& truth, const ImageU8* excluded);

/// @brief Mean 3D end-point error [m] of scene flow, same pixel selection.
double sceneFlowEpe(const ImageF& estimate, const ImageF& truth, const ImageU8* excluded, std::size_t* pixels = nullptr);

/// @brief Table 1: warp frame 2 back with the scene flow (P2 = P + flow, sampled at pi(P2)) and take the
/// RMSE of I1 - I2(pi(P2)) and of [P2]_z - Z2(pi(P2)) over valid, non-excluded pixels.
/// A null scene flow means zero flow.
ResidualRmse warpResidualRmse(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K,
                              const ImageF* scene_flow, const ImageU8* excluded);

/// @brief Fraction of pixels (truth >= 0 and estimate >= 0) whose estimated segment maps to their true part
/// under the best one-to-one matching (greedy on overlap).
double segmentationAgreement(const ImageI32& estimate, const ImageI32& truth);

/// @brief Fraction of valid pixels where two binary masks (non-zero = set) agree; `valid` may be null.
double maskAgreement(const ImageU8& a, const ImageU8& b, const ImageU8* valid);

}  // namespace mc_flow
