// Device versions of the sampling helpers of include/mc_flow/core/sampling.h for the CUDA motion step.
//
// Each float operation is rounded on its own (mc_flow/core/rounded.h), in the order the CPU code evaluates
// it, so a sample and the in-view decision match the CPU's bit for bit.
// Included by cuda/*.cu only.
#pragma once

#include <cuda_runtime.h>

#include "mc_flow/core/rounded.h"
#include "mc_flow/core/sampling.h"

namespace mc_flow {
namespace cuda_detail {

/// @brief An image on the device: row-major, `channels` interleaved floats per pixel.
struct DeviceImage {
  const float* data = nullptr;
  int width = 0, height = 0, channels = 1;
  __device__ __forceinline__ float at(int x, int y, int c) const {
    return __ldg(data + (static_cast<size_t>(y) * width + x) * channels + c);
  }
};

/// @brief sampleBilinear of sampling.h.
__device__ __forceinline__ bool sampleBilinearDevice(const DeviceImage& im, float x, float y, int c, float& out) {
  if (!(x >= 0.f && y >= 0.f && x <= float(im.width - 1) && y <= float(im.height - 1))) return false;
  const int x0 = int(x), y0 = int(y);
  const int x1 = x0 + 1 < im.width ? x0 + 1 : x0, y1 = y0 + 1 < im.height ? y0 + 1 : y0;
  const float ax = subRn(x, float(x0)), ay = subRn(y, float(y0));
  const float bx = subRn(1.f, ax), by = subRn(1.f, ay);
  const float top = addRn(mulRn(bx, im.at(x0, y0, c)), mulRn(ax, im.at(x1, y0, c)));
  const float bottom = addRn(mulRn(bx, im.at(x0, y1, c)), mulRn(ax, im.at(x1, y1, c)));
  out = addRn(mulRn(by, top), mulRn(ay, bottom));
  return true;
}

/// @brief sampleDepthBilinearSmooth of sampling.h (valid corners only, renormalised; false across a jump
/// larger than `max_jump` metres).
__device__ __forceinline__ bool sampleDepthBilinearSmoothDevice(const DeviceImage& depth, float x, float y,
                                                                float max_jump, float& out) {
  if (!(x >= 0.f && y >= 0.f && x <= float(depth.width - 1) && y <= float(depth.height - 1))) return false;
  const int x0 = int(x), y0 = int(y);
  const int x1 = x0 + 1 < depth.width ? x0 + 1 : x0, y1 = y0 + 1 < depth.height ? y0 + 1 : y0;
  const float ax = subRn(x, float(x0)), ay = subRn(y, float(y0));
  const float bx = subRn(1.f, ax), by = subRn(1.f, ay);
  const float w[4] = {mulRn(bx, by), mulRn(ax, by), mulRn(bx, ay), mulRn(ax, ay)};
  const float z[4] = {depth.at(x0, y0, 0), depth.at(x1, y0, 0), depth.at(x0, y1, 0), depth.at(x1, y1, 0)};
  float sw = 0.f, sz = 0.f, lo = 1e30f, hi = 0.f;
#pragma unroll
  for (int k = 0; k < 4; ++k) {
    if (z[k] > 0.f) {
      sw = addRn(sw, w[k]);
      sz = addRn(sz, mulRn(w[k], z[k]));
      lo = z[k] < lo ? z[k] : lo;
      hi = z[k] > hi ? z[k] : hi;
    }
  }
  if (sw < 0.5f) return false;
  out = divRn(sz, sw);
  return subRn(hi, lo) <= max_jump;
}

}  // namespace cuda_detail
}  // namespace mc_flow
