/**
 * @file occlusion.h
 * @brief Occlusion mask (section 6): warp count C(W(x)) plus the depth test, thresholded.
 */
#pragma once

#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"

namespace mc_flow {

/// @brief O(x) = 1 if C(W(x)) + K_z * O_Z(x) > K_o, with C the number of frame-1 pixels whose warp lands
/// on each frame-2 pixel (nearest pixel), and O_Z(x) = [g P(x)]_z - Z2(W(x)) (the z-buffer form of the
/// paper's temporal depth change: positive when the warped point lies behind what frame 2 sees).
/// Points warped out of the image are occluded. Returns 255 / 0 per pixel; invalid points are 0.
ImageU8 detectOcclusions(const ImageF& warped_points, const ImageF& depth2, const Intrinsics& K, const Config& config);

}  // namespace mc_flow
