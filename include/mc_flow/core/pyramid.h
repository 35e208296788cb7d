/**
 * @file pyramid.h
 * @brief Coarse-to-fine intensity/depth pyramids with back-projected points and image gradients.
 */
#pragma once

#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"

namespace mc_flow {

/// @brief One pyramid level of one frame.
struct PyramidLevel {
  ImageF intensity;       ///< [0, 1]
  ImageF depth;           ///< [m], 0 = invalid (NaN never appears inside the pyramid)
  ImageF points;          ///< 3 channels X, Y, Z [m] in the camera frame; NaN where depth is invalid
  ImageF intensity_grad;  ///< 2 channels d/dx, d/dy [1/px]
  ImageF depth_grad;      ///< 2 channels d/dx, d/dy [m/px]; 0 next to invalid depth
  Intrinsics intrinsics;  ///< of this level
  int validCount() const;
};

/// @brief Levels from fine (index 0 = input resolution) to coarse.
struct Pyramid {
  std::vector<PyramidLevel> levels;
  int size() const { return int(levels.size()); }
  const PyramidLevel& operator[](int i) const { return levels[std::size_t(i)]; }
};

/// @brief Number of levels so that the coarsest is at least `coarsest_min_width` wide (>= 1).
int pyramidLevelCount(int width, int height, int coarsest_min_width);

/// @brief Width (or height) of pyramid level `level` for an input `n` pixels wide (or high): halved `level`
/// times with integer division (an odd last column or row is dropped), at least 1.
int pyramidLevelExtent(int n, int level);

/// @brief Halves an intensity image with a separable [1 3 3 1]/8 kernel (clamped borders).
ImageF downsampleIntensity(const ImageF& image);

/// @brief Halves a depth image without mixing across depth discontinuities or invalid pixels:
/// each output pixel averages (with [1 3 3 1] weights) only the valid inputs of its 4x4 window within
/// `range` metres of the median of the valid values of its central 2x2 block; 0 if none.
ImageF downsampleDepth(const ImageF& depth, double range);

/// @brief Back-projects depth into 3 channel points (NaN where invalid).
ImageF backProject(const ImageF& depth, const Intrinsics& K);

/// @brief Gradient of f blending the one-sided differences towards the smaller one (PD-Flow style);
/// pixels whose neighbours are invalid (mask 0) use the remaining one-sided difference or 0.
ImageF blendedGradient(const ImageF& f, const ImageF* validity_source, float eps);

/// @brief Builds `levels` levels; depth is cleaned first (outside [min_depth, max_depth] or NaN -> 0).
Pyramid buildPyramid(const RgbdFrame& frame, const Intrinsics& K, int levels, const Config& config);

}  // namespace mc_flow
