// Device images and the sampling functions of include/mc_flow/core/sampling.h on them (the rule itself is written
// once there, with every float operation rounded on its own, so a sample matches the CPU's bit for bit).
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

/// Channel c of a device image, as the accessor of sampling.h's functions.
struct DeviceChannel {
  const DeviceImage& image;
  int c;
  __device__ __forceinline__ float operator()(int x, int y) const { return image.at(x, y, c); }
};

/// @brief sampleBilinearAt of sampling.h on a device image.
__device__ __forceinline__ bool sampleBilinearDevice(const DeviceImage& im, float x, float y, int c, float& out) {
  return sampleBilinearAt(DeviceChannel{im, c}, im.width, im.height, x, y, out);
}

/// @brief sampleDepthBilinearAt of sampling.h on a device depth image.
__device__ __forceinline__ bool sampleDepthBilinearDevice(const DeviceImage& depth, float x, float y, float& out) {
  return sampleDepthBilinearAt(DeviceChannel{depth, 0}, depth.width, depth.height, x, y, out);
}

/// @brief sampleDepthBilinearSmoothAt of sampling.h on a device depth image.
__device__ __forceinline__ bool sampleDepthBilinearSmoothDevice(const DeviceImage& depth, float x, float y,
                                                                float max_jump, float& out) {
  return sampleDepthBilinearSmoothAt(DeviceChannel{depth, 0}, depth.width, depth.height, x, y, max_jump, out);
}

}  // namespace cuda_detail
}  // namespace mc_flow
