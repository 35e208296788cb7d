/**
 * @file sampling.h
 * @brief Bilinear sampling helpers shared by the motion, label and occlusion stages.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/image.h"

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

/// @brief Bilinear sample of channel c at (x, y); false when outside [0, w-1] x [0, h-1].
inline bool sampleBilinear(const ImageF& im, float x, float y, int c, float& out) {
  if (!(x >= 0.f && y >= 0.f && x <= float(im.width - 1) && y <= float(im.height - 1))) return false;
  int x0 = int(x), y0 = int(y);
  int x1 = x0 + 1 < im.width ? x0 + 1 : x0, y1 = y0 + 1 < im.height ? y0 + 1 : y0;
  float ax = x - float(x0), ay = y - float(y0);
  out = (1 - ay) * ((1 - ax) * im(x0, y0, c) + ax * im(x1, y0, c)) + ay * ((1 - ax) * im(x0, y1, c) + ax * im(x1, y1, c));
  return true;
}

/// @brief Bilinear sample of a depth image that uses only valid (> 0) corners, renormalising their
/// weights; false outside the image or when the valid corners carry less than half the weight.
inline bool sampleDepthBilinear(const ImageF& depth, float x, float y, float& out) {
  if (!(x >= 0.f && y >= 0.f && x <= float(depth.width - 1) && y <= float(depth.height - 1))) return false;
  int x0 = int(x), y0 = int(y);
  int x1 = x0 + 1 < depth.width ? x0 + 1 : x0, y1 = y0 + 1 < depth.height ? y0 + 1 : y0;
  float ax = x - float(x0), ay = y - float(y0);
  const float w[4] = {(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay};
  const float z[4] = {depth(x0, y0), depth(x1, y0), depth(x0, y1), depth(x1, y1)};
  float sw = 0, sz = 0;
  for (int k = 0; k < 4; ++k)
    if (z[k] > 0.f) { sw += w[k]; sz += w[k] * z[k]; }
  if (sw < 0.5f) return false;
  out = sz / sw;
  return true;
}

/// @brief Like sampleDepthBilinear, but also false when the valid corners differ by more than `max_jump`
/// metres: across a depth discontinuity the interpolated value belongs to no surface, and its linearisation
/// (the depth gradient) says nothing about how it changes with the warp.
inline bool sampleDepthBilinearSmooth(const ImageF& depth, float x, float y, float max_jump, float& out) {
  if (!sampleDepthBilinear(depth, x, y, out)) return false;
  const int x0 = int(x), y0 = int(y);
  const int x1 = x0 + 1 < depth.width ? x0 + 1 : x0, y1 = y0 + 1 < depth.height ? y0 + 1 : y0;
  float lo = 1e30f, hi = 0.f;
  for (float z : {depth(x0, y0), depth(x1, y0), depth(x0, y1), depth(x1, y1)})
    if (z > 0.f) {
      lo = z < lo ? z : lo;
      hi = z > hi ? z : hi;
    }
  return hi - lo <= max_jump;
}

}  // namespace mc_flow
