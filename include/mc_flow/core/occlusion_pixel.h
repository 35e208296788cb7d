/**
 * @file occlusion_pixel.h
 * @brief The occlusion test's per-pixel rules (section 6), written once for the CPU (src/core/occlusion.cpp) and the
 * CUDA kernels (cuda/occlusion.cu): the frame-2 pixel a warped point lands on, and the z-buffer test there.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/rounded.h"

namespace mc_flow {
namespace occlusion_pixel {

/// @brief Index of the nearest frame-2 pixel of the warped point P (finite), or -1 when it is behind the camera or
/// outside the width x height image.
MCFLOW_HOST_DEVICE inline long long targetPixel(const float P[3], double fx, double fy, double cx, double cy, int width,
                                                int height) {
  if (!(P[2] > 0.f)) return -1;
  const double u = fx * P[0] / P[2] + cx, v = fy * P[1] / P[2] + cy;
  const double ur = std::floor(u + 0.5), vr = std::floor(v + 0.5);
  if (!(ur >= 0 && vr >= 0 && ur < width && vr < height)) return -1;
  return (long long)(vr)*width + (long long)(ur);
}

/// @brief Whether a point warped to depth z onto a target pixel that `count` points reach, where frame 2 sees depth
/// z2, is occluded: count + kz (z - z2) > ko, the depth change counted only where z2 is valid (the z-buffer form: it
/// is positive when the warped point lies behind what frame 2 sees).
MCFLOW_HOST_DEVICE inline bool occluded(int count, float z, float z2, float kz, float ko) {
  const bool valid = z2 > 0.f && z2 <= 3.402823466e38f;  // finite and positive (NaN fails both)
  const float depth_change = valid ? subRn(z, z2) : 0.f;
  return addRn(float(count), mulRn(kz, depth_change)) > ko;
}

}  // namespace occlusion_pixel
}  // namespace mc_flow
