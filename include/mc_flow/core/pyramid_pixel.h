/**
 * @file pyramid_pixel.h
 * @brief The pyramid's per-pixel rules, written once for the CPU stage (src/core/pyramid.cpp) and the CUDA
 * one (cuda/pyramid.cu). Images are read through an accessor `at(x, y)`, so the same function runs on host
 * images and on device pointers; every float operation is rounded on its own (rounded.h), so both backends
 * build the same pyramid bit for bit.
 */
#pragma once

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/rounded.h"

namespace mc_flow {
namespace pyramid_pixel {

constexpr float kIntensityGradientEps = 1e-6f;  // docs/ALGORITHM.md, 'Gradients' (the PD-Flow blend)
constexpr float kDepthGradientEps = 0.005f;     // [m]

MCFLOW_HOST_DEVICE inline int clampIndex(int i, int n) { return i < 0 ? 0 : (i >= n ? n - 1 : i); }

/// @brief Finite and positive (NaN fails both comparisons).
MCFLOW_HOST_DEVICE inline bool validDepth(float z) { return z > 0.f && z <= 3.402823466e38f; }

/// @brief Depth outside [min_depth, max_depth] (or NaN, inf) becomes 0, the pyramid's "invalid".
MCFLOW_HOST_DEVICE inline float cleanDepth(float z, float min_depth, float max_depth) {
  return (z >= min_depth && z <= max_depth) ? z : 0.f;
}

/// @brief The [1 3 3 1] / 8 filter of four samples, summed in order from zero.
MCFLOW_HOST_DEVICE inline float filter1331(float a, float b, float c, float d) {
  float s = addRn(0.f, mulRn(0.125f, a));
  s = addRn(s, mulRn(0.375f, b));
  s = addRn(s, mulRn(0.375f, c));
  return addRn(s, mulRn(0.125f, d));
}

/// @brief Horizontal half of downsampleIntensity: output column x of input row y (clamped borders).
template <typename At>
MCFLOW_HOST_DEVICE float downsampleRow(const At& at, int width, int x, int y) {
  return filter1331(at(clampIndex(2 * x - 1, width), y), at(clampIndex(2 * x, width), y),
                    at(clampIndex(2 * x + 1, width), y), at(clampIndex(2 * x + 2, width), y));
}

/// @brief Output pixel (x, y) of downsampleIntensity (separable, clamped borders); `at` reads the input.
template <typename At>
MCFLOW_HOST_DEVICE float downsampledIntensity(const At& at, int width, int height, int x, int y) {
  return filter1331(downsampleRow(at, width, x, clampIndex(2 * y - 1, height)),
                    downsampleRow(at, width, x, clampIndex(2 * y, height)),
                    downsampleRow(at, width, x, clampIndex(2 * y + 1, height)),
                    downsampleRow(at, width, x, clampIndex(2 * y + 2, height)));
}

/// @brief Output pixel (x, y) of downsampleDepth: the [1 3 3 1] weighted mean of the valid inputs of the 4x4
/// window within `max_diff` metres of the lower median of the valid central 2x2 block; 0 if that block has
/// none. The reference is an actual sample (never the mean of two), so a block straddling an edge picks one
/// side instead of a phantom depth between them.
template <typename At>
MCFLOW_HOST_DEVICE float downsampledDepth(const At& at, int width, int height, int x, int y, float max_diff) {
  float centre[4];
  int n = 0;
  for (int dy = 0; dy < 2; ++dy)
    for (int dx = 0; dx < 2; ++dx) {
      const float z = at(2 * x + dx < width ? 2 * x + dx : width - 1, 2 * y + dy < height ? 2 * y + dy : height - 1);
      if (validDepth(z)) centre[n++] = z;
    }
  if (n == 0) return 0.f;
  for (int i = 1; i < n; ++i)  // insertion sort of at most four values
    for (int j = i; j > 0 && centre[j] < centre[j - 1]; --j) {
      const float t = centre[j];
      centre[j] = centre[j - 1];
      centre[j - 1] = t;
    }
  const float reference = centre[(n - 1) / 2];
  const float k[4] = {1.f, 3.f, 3.f, 1.f};
  float sum_w = 0.f, sum_z = 0.f;
  for (int t = 0; t < 4; ++t) {
    const int yi = 2 * y - 1 + t;
    if (yi < 0 || yi >= height) continue;
    for (int s = 0; s < 4; ++s) {
      const int xi = 2 * x - 1 + s;
      if (xi < 0 || xi >= width) continue;
      const float z = at(xi, yi);
      if (!validDepth(z) || absF(subRn(z, reference)) > max_diff) continue;
      const float weight = mulRn(k[t], k[s]);
      sum_w = addRn(sum_w, weight);
      sum_z = addRn(sum_z, mulRn(weight, z));
    }
  }
  return divRn(sum_z, sum_w);  // the reference itself always passes, so sum_w > 0
}

/// @brief The 3D point of pixel (x, y) with depth z (valid), for 1/fx, 1/fy and the principal point.
MCFLOW_HOST_DEVICE inline void backProjectPixel(float z, int x, int y, double cx, double cy, double inv_fx,
                                                double inv_fy, float P[3]) {
  P[0] = mulRn(z, float((x - cx) * inv_fx));
  P[1] = mulRn(z, float((y - cy) * inv_fy));
  P[2] = z;
}

/// @brief One-dimensional blended derivative from the backward (f0 - fm) and forward (fp - f0) differences:
/// each is weighted by the other's magnitude, so the smaller one dominates (the PD-Flow blend).
MCFLOW_HOST_DEVICE inline float blendedDifference(float backward, float forward, float eps) {
  const float r_back = addRn(absF(backward), eps), r_fwd = addRn(absF(forward), eps);
  return divRn(addRn(mulRn(r_back, forward), mulRn(r_fwd, backward)), addRn(r_back, r_fwd));
}

/// @brief blendedGradient at (x, y): per axis, the blend of both one-sided differences when both neighbours
/// are usable (`usable(x, y)`), else the one left, else 0; 0 where (x, y) itself is not usable.
template <typename At, typename Usable>
MCFLOW_HOST_DEVICE void blendedGradientAt(const At& at, const Usable& usable, int width, int height, int x, int y,
                                          float eps, float gradient[2]) {
  gradient[0] = gradient[1] = 0.f;
  if (!usable(x, y)) return;
  const float f0 = at(x, y);
  for (int axis = 0; axis < 2; ++axis) {
    const int xm = axis == 0 ? x - 1 : x, ym = axis == 0 ? y : y - 1;
    const int xp = axis == 0 ? x + 1 : x, yp = axis == 0 ? y : y + 1;
    const bool has_m = xm >= 0 && ym >= 0 && usable(xm, ym);
    const bool has_p = xp < width && yp < height && usable(xp, yp);
    if (has_m && has_p)
      gradient[axis] = blendedDifference(subRn(f0, at(xm, ym)), subRn(at(xp, yp), f0), eps);
    else if (has_m)
      gradient[axis] = subRn(f0, at(xm, ym));
    else if (has_p)
      gradient[axis] = subRn(at(xp, yp), f0);
  }
}

}  // namespace pyramid_pixel
}  // namespace mc_flow
