// The pyramid stage on the device (src/core/pyramid.cpp is the reference): each frame goes up once, and every
// level, its points and its gradients are built here from the per-pixel rules of mc_flow/core/pyramid_pixel.h,
// the CPU's own functions, so both backends start from the same pyramids bit for bit.
#include <cuda_runtime.h>

#include <cstdint>
#include <vector>

#include "cuda_check.h"
#include "device_stages.h"
#include "mc_flow/core/pyramid_pixel.h"

namespace mc_flow {
namespace cuda_detail {

namespace {

constexpr int kBlockX = 32, kBlockY = 8;
constexpr int kCountThreads = 256;

dim3 gridFor(int width, int height) {
  return dim3(unsigned((width + kBlockX - 1) / kBlockX), unsigned((height + kBlockY - 1) / kBlockY));
}

__global__ void cleanDepthKernel(float* __restrict__ depth, std::size_t n, float min_depth, float max_depth) {
  const std::size_t i = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n) depth[i] = pyramid_pixel::cleanDepth(depth[i], min_depth, max_depth);
}

__global__ void downsampleKernel(const float* __restrict__ intensity, const float* __restrict__ depth, int w, int h,
                                 float* __restrict__ out_intensity, float* __restrict__ out_depth, int ow, int oh,
                                 float max_diff) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= ow || y >= oh) return;
  const auto intensity_at = [&](int xi, int yi) { return __ldg(intensity + std::size_t(yi) * w + xi); };
  const auto depth_at = [&](int xi, int yi) { return __ldg(depth + std::size_t(yi) * w + xi); };
  const std::size_t o = std::size_t(y) * ow + x;
  out_intensity[o] = pyramid_pixel::downsampledIntensity(intensity_at, w, h, x, y);
  out_depth[o] = pyramid_pixel::downsampledDepth(depth_at, w, h, x, y, max_diff);
}

__global__ void pointsKernel(const float* __restrict__ depth, int w, int h, double cx, double cy, double inv_fx,
                             double inv_fy, float* __restrict__ points) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= w || y >= h) return;
  const std::size_t i = std::size_t(y) * w + x;
  const float z = depth[i];
  float* P = points + 3 * i;
  if (pyramid_pixel::validDepth(z)) {
    pyramid_pixel::backProjectPixel(z, x, y, cx, cy, inv_fx, inv_fy, P);
  } else {
    P[0] = P[1] = P[2] = __int_as_float(0x7fc00000);  // quiet NaN, as the CPU's
  }
}

__global__ void gradientsKernel(const float* __restrict__ intensity, const float* __restrict__ depth, int w, int h,
                                float* __restrict__ intensity_grad, float* __restrict__ depth_grad) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= w || y >= h) return;
  const std::size_t i = std::size_t(y) * w + x;
  const auto intensity_at = [&](int xi, int yi) { return __ldg(intensity + std::size_t(yi) * w + xi); };
  const auto depth_at = [&](int xi, int yi) { return __ldg(depth + std::size_t(yi) * w + xi); };
  const auto everywhere = [](int, int) { return true; };
  const auto where_depth = [&](int xi, int yi) { return pyramid_pixel::validDepth(depth_at(xi, yi)); };
  pyramid_pixel::blendedGradientAt(intensity_at, everywhere, w, h, x, y, pyramid_pixel::kIntensityGradientEps,
                                   intensity_grad + 2 * i);
  pyramid_pixel::blendedGradientAt(depth_at, where_depth, w, h, x, y, pyramid_pixel::kDepthGradientEps,
                                   depth_grad + 2 * i);
}

// Valid pixels of one level, added into *count (integer atomics: the order does not matter).
__global__ void countValidKernel(const float* __restrict__ depth, std::size_t n, int* __restrict__ count) {
  const std::size_t i = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const int valid = __syncthreads_count(i < n && pyramid_pixel::validDepth(depth[i]));
  if (threadIdx.x == 0 && valid > 0) atomicAdd(count, valid);
}

}  // namespace

void launchBuildPyramid(const std::vector<DevicePyramidLevel>& levels, const Config& config, int* valid_counts,
                        cudaStream_t stream) {
  if (levels.empty()) return;
  const DevicePyramidLevel& base = levels.front();
  const std::size_t base_plane = std::size_t(base.width) * base.height;
  cleanDepthKernel<<<unsigned((base_plane + 255) / 256), 256, 0, stream>>>(
      base.depth, base_plane, float(config.min_depth), float(config.max_depth));
  MCFLOW_CUDA_CHECK_LAUNCH("cleanDepthKernel");
  if (valid_counts) MCFLOW_CUDA_CHECK(cudaMemsetAsync(valid_counts, 0, levels.size() * sizeof(int), stream));
  for (std::size_t l = 0; l < levels.size(); ++l) {
    const DevicePyramidLevel& L = levels[l];
    if (l > 0) {
      const DevicePyramidLevel& finer = levels[l - 1];
      downsampleKernel<<<gridFor(L.width, L.height), dim3(kBlockX, kBlockY), 0, stream>>>(
          finer.intensity, finer.depth, finer.width, finer.height, L.intensity, L.depth, L.width, L.height,
          float(config.depth_downsample_range));
      MCFLOW_CUDA_CHECK_LAUNCH("downsampleKernel");
    }
    if (L.points) {
      pointsKernel<<<gridFor(L.width, L.height), dim3(kBlockX, kBlockY), 0, stream>>>(
          L.depth, L.width, L.height, L.intrinsics.cx, L.intrinsics.cy, 1.0 / L.intrinsics.fx, 1.0 / L.intrinsics.fy,
          L.points);
      MCFLOW_CUDA_CHECK_LAUNCH("pointsKernel");
    }
    if (L.intensity_grad && L.depth_grad) {
      gradientsKernel<<<gridFor(L.width, L.height), dim3(kBlockX, kBlockY), 0, stream>>>(
          L.intensity, L.depth, L.width, L.height, L.intensity_grad, L.depth_grad);
      MCFLOW_CUDA_CHECK_LAUNCH("gradientsKernel");
    }
    if (valid_counts) {
      const std::size_t plane = std::size_t(L.width) * L.height;
      countValidKernel<<<unsigned((plane + kCountThreads - 1) / kCountThreads), kCountThreads, 0, stream>>>(
          L.depth, plane, valid_counts + l);
      MCFLOW_CUDA_CHECK_LAUNCH("countValidKernel");
    }
  }
}

}  // namespace cuda_detail
}  // namespace mc_flow
