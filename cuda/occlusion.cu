// Occlusion mask of the device-resident solve: warpPoints (src/core/scene_flow.cpp) followed by
// detectOcclusions (src/core/occlusion.cpp, the reference) at one pyramid level, with the rules of
// scene_flow_pixel.h and occlusion_pixel.h. The warp runs in double
// as on the CPU; the per-target counts are integer atomics (order-independent), so the mask is the CPU's
// up to the last bit of the blended twists' sums.
#include <cuda_runtime.h>

#include <cstdint>

#include "cuda_check.h"
#include "device_stages.h"
#include "mc_flow/core/occlusion_pixel.h"

namespace mc_flow {
namespace cuda_detail {

namespace {

constexpr int kThreads = 256;

struct OcclusionParams {
  DeviceLevel level;
  const float* u;
  int count;
  const double* motions;  // 18 per motion label: twist, rows 0..2 of exp(twist)
  float kz, ko;
};

// Warps one pixel with its interpolated motion; writes the target pixel (-1: behind the camera or out of view;
// -2: no valid point) and the warped depth.
__global__ void warpKernel(const OcclusionParams q, long long* __restrict__ targets, float* __restrict__ warped_z,
                           int* __restrict__ counts) {
  const int W = q.level.width, H = q.level.height;
  const std::size_t plane = std::size_t(W) * H;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const int x = int(idx % std::size_t(W)), y = int(idx / std::size_t(W));
  const DeviceImage& pts = q.level.points1;
  const float P[3] = {pts.at(x, y, 0), pts.at(x, y, 1), pts.at(x, y, 2)};
  if (!(isfinite(P[0]) && isfinite(P[1]) && isfinite(P[2]))) {
    targets[idx] = -2;
    return;
  }
  double Q[3];
  warpPointDevice(P, q.u, plane, idx, q.count - 1, q.motions, Q);
  const float Qf[3] = {float(Q[0]), float(Q[1]), float(Q[2])};
  warped_z[idx] = Qf[2];
  const Intrinsics& K = q.level.intrinsics;
  const long long target = occlusion_pixel::targetPixel(Qf, K.fx, K.fy, K.cx, K.cy, W, H);
  targets[idx] = target;
  if (target >= 0) atomicAdd(counts + target, 1);
}

__global__ void occlusionTestKernel(const OcclusionParams q, const long long* __restrict__ targets,
                                    const float* __restrict__ warped_z, const int* __restrict__ counts,
                                    std::uint8_t* __restrict__ occluded) {
  const std::size_t plane = std::size_t(q.level.width) * q.level.height;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const long long t = targets[idx];
  std::uint8_t mask = 0;
  if (t == -1) {
    mask = 255;  // out of view (or behind the camera) in frame 2
  } else if (t >= 0) {
    if (occlusion_pixel::occluded(counts[t], warped_z[idx], q.level.depth2.data[t], q.kz, q.ko)) mask = 255;
  }
  occluded[idx] = mask;
}

}  // namespace

void launchOcclusion(const DeviceLevel& level, const float* u, int count, const double* motions, const Config& config,
                     int* counts, long long* targets, float* warped_z, std::uint8_t* occluded, cudaStream_t stream) {
  const OcclusionParams q{level, u, count, motions, float(config.occlusion_kz), float(config.occlusion_ko)};
  const std::size_t plane = std::size_t(level.width) * level.height;
  const unsigned blocks = unsigned((plane + kThreads - 1) / kThreads);
  MCFLOW_CUDA_CHECK(cudaMemsetAsync(counts, 0, plane * sizeof(int), stream));
  warpKernel<<<blocks, kThreads, 0, stream>>>(q, targets, warped_z, counts);
  MCFLOW_CUDA_CHECK_LAUNCH("warpKernel");
  occlusionTestKernel<<<blocks, kThreads, 0, stream>>>(q, targets, warped_z, counts, occluded);
  MCFLOW_CUDA_CHECK_LAUNCH("occlusionTestKernel");
}

}  // namespace cuda_detail
}  // namespace mc_flow
