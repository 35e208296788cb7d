/**
 * @file sampling.h
 * @brief Bilinear sampling, written once for the CPU stages and the CUDA kernels (through an accessor `at(x, y)`,
 * as pyramid_pixel.h does), shared by the motion and label steps.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/rounded.h"

namespace mc_flow {

/// @brief How far [px] beyond the outermost pixel centres a warp still counts as in view (sampled at the
/// clamped position). Shared by the motion and label steps so both price a warp near the border alike; a
/// zero margin would flip whole border columns between "seen" and "out of view" on sub-pixel steps.
constexpr float kBorderMargin = 2.f;

/// @brief Clamps (x, y) into the image when it lies within kBorderMargin of it; false when farther out
/// (out of view) or not finite.
MCFLOW_HOST_DEVICE inline bool clampIntoView(int width, int height, float& x, float& y) {
  if (!(x >= -kBorderMargin && y >= -kBorderMargin && x <= float(width - 1) + kBorderMargin &&
        y <= float(height - 1) + kBorderMargin))
    return false;
  x = x < 0.f ? 0.f : (x > float(width - 1) ? float(width - 1) : x);
  y = y < 0.f ? 0.f : (y > float(height - 1) ? float(height - 1) : y);
  return true;
}

/// @brief Bilinear sample at (x, y) of a single-channel image read through `at(xi, yi)`; false when outside
/// [0, w-1] x [0, h-1]. Every float operation is rounded on its own (rounded.h), so the CPU stages (sampleBilinear
/// below) and the CUDA kernels (cuda/sampling_device.cuh) sample the same bits.
template <typename At>
MCFLOW_HOST_DEVICE bool sampleBilinearAt(const At& at, int width, int height, float x, float y, float& out) {
  if (!(x >= 0.f && y >= 0.f && x <= float(width - 1) && y <= float(height - 1))) return false;
  const int x0 = int(x), y0 = int(y);
  const int x1 = x0 + 1 < width ? x0 + 1 : x0, y1 = y0 + 1 < height ? y0 + 1 : y0;
  const float ax = subRn(x, float(x0)), ay = subRn(y, float(y0));
  const float bx = subRn(1.f, ax), by = subRn(1.f, ay);
  const float top = addRn(mulRn(bx, at(x0, y0)), mulRn(ax, at(x1, y0)));
  const float bottom = addRn(mulRn(bx, at(x0, y1)), mulRn(ax, at(x1, y1)));
  out = addRn(mulRn(by, top), mulRn(ay, bottom));
  return true;
}

/// @brief Bilinear sample of a depth image read through `at(xi, yi)` that uses only valid (> 0) corners,
/// renormalising their weights; false outside the image or when the valid corners carry less than half the weight.
/// `span` (may be null) receives the largest minus the smallest valid corner [m].
template <typename At>
MCFLOW_HOST_DEVICE bool sampleDepthBilinearAt(const At& at, int width, int height, float x, float y, float& out,
                                              float* span = nullptr) {
  if (!(x >= 0.f && y >= 0.f && x <= float(width - 1) && y <= float(height - 1))) return false;
  const int x0 = int(x), y0 = int(y);
  const int x1 = x0 + 1 < width ? x0 + 1 : x0, y1 = y0 + 1 < height ? y0 + 1 : y0;
  const float ax = subRn(x, float(x0)), ay = subRn(y, float(y0));
  const float bx = subRn(1.f, ax), by = subRn(1.f, ay);
  const float w[4] = {mulRn(bx, by), mulRn(ax, by), mulRn(bx, ay), mulRn(ax, ay)};
  const float z[4] = {at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1)};
  float sw = 0.f, sz = 0.f, lo = 1e30f, hi = 0.f;
  MCFLOW_UNROLL
  for (int k = 0; k < 4; ++k)
    if (z[k] > 0.f) {
      sw = addRn(sw, w[k]);
      sz = addRn(sz, mulRn(w[k], z[k]));
      lo = z[k] < lo ? z[k] : lo;
      hi = z[k] > hi ? z[k] : hi;
    }
  if (sw < 0.5f) return false;
  out = divRn(sz, sw);
  if (span) *span = subRn(hi, lo);
  return true;
}

/// @brief Like sampleDepthBilinearAt, but also false when the valid corners differ by more than `max_jump`
/// metres: across a depth discontinuity the interpolated value belongs to no surface, and its linearisation
/// (the depth gradient) says nothing about how it changes with the warp.
template <typename At>
MCFLOW_HOST_DEVICE bool sampleDepthBilinearSmoothAt(const At& at, int width, int height, float x, float y,
                                                    float max_jump, float& out) {
  float span = 0.f;
  return sampleDepthBilinearAt(at, width, height, x, y, out, &span) && span <= max_jump;
}

namespace sampling_detail {
/// Channel c of a host image, as the accessor of the functions above.
struct HostChannel {
  const ImageF& image;
  int c;
  float operator()(int x, int y) const { return image(x, y, c); }
};
}  // namespace sampling_detail

/// @brief Bilinear sample of channel c at (x, y); false when outside [0, w-1] x [0, h-1].
inline bool sampleBilinear(const ImageF& im, float x, float y, int c, float& out) {
  return sampleBilinearAt(sampling_detail::HostChannel{im, c}, im.width, im.height, x, y, out);
}

/// @brief sampleDepthBilinearAt of a host depth image.
inline bool sampleDepthBilinear(const ImageF& depth, float x, float y, float& out) {
  return sampleDepthBilinearAt(sampling_detail::HostChannel{depth, 0}, depth.width, depth.height, x, y, out);
}

/// @brief sampleDepthBilinearSmoothAt of a host depth image.
inline bool sampleDepthBilinearSmooth(const ImageF& depth, float x, float y, float max_jump, float& out) {
  return sampleDepthBilinearSmoothAt(sampling_detail::HostChannel{depth, 0}, depth.width, depth.height, x, y, max_jump,
                                     out);
}

}  // namespace mc_flow
