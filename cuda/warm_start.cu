// Stream mode on the device: the previous pair's segment ids carried onto the next frame 1 and resampled to the label
// level (src/core/warm_start.cpp's carryIds and carriedLabelsAtLevel, with warm_start_pixel.h's rules: the same ids
// bit for bit).
#include "device_stages.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/warm_start_pixel.h"

namespace mc_flow {
namespace cuda_detail {
namespace {

constexpr int kThreads = 256;

unsigned blocksFor(std::size_t pixels) { return unsigned((pixels + kThreads - 1) / kThreads); }

// Each labelled point lands where its optical flow takes it; the pixel keeps the smallest key (nearest, then first).
__global__ void splatKernel(const int* __restrict__ ids, const float* __restrict__ optical_flow,
                            const float* __restrict__ moved_depth, int width, int height,
                            unsigned long long* __restrict__ winner) {
  const std::size_t k = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (k >= std::size_t(width) * height || ids[k] <= 0) return;
  const int x = int(k % std::size_t(width)), y = int(k / std::size_t(width));
  int tx = 0, ty = 0;
  std::uint64_t key = 0;
  if (!warm_start_pixel::splatTarget(x, y, optical_flow[2 * k], optical_flow[2 * k + 1], width, height, tx, ty) ||
      !warm_start_pixel::splatKey(moved_depth[k], std::uint32_t(k), key))
    return;
  atomicMin(winner + std::size_t(ty) * width + tx, static_cast<unsigned long long>(key));
}

// The winner's id where its moved depth agrees with the observed one.
__global__ void keepKernel(const unsigned long long* __restrict__ winner, const int* __restrict__ ids,
                           const float* __restrict__ depth, std::size_t pixels, double tolerance,
                           int* __restrict__ carried) {
  const std::size_t k = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (k >= pixels) return;
  const std::uint64_t key = winner[k];
  carried[k] = key != warm_start_pixel::kNoWinner &&
                       warm_start_pixel::keepsId(warm_start_pixel::keyDepth(key), depth[k], tolerance)
                   ? ids[warm_start_pixel::keySource(key)]
                   : 0;
}

__global__ void closeGapsKernel(const int* __restrict__ carried, const float* __restrict__ depth, int width, int height,
                                double tolerance, int* __restrict__ closed) {
  const std::size_t k = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (k >= std::size_t(width) * height) return;
  const int x = int(k % std::size_t(width)), y = int(k / std::size_t(width));
  const auto id_at = [&](int px, int py) { return carried[std::size_t(py) * width + px]; };
  const auto depth_at = [&](int px, int py) { return depth[std::size_t(py) * width + px]; };
  closed[k] = warm_start_pixel::closedGapId(id_at, depth_at, width, height, x, y, tolerance);
}

// Each level pixel's majority id (-1: no depth, 0: none); a block holds at most kMaxMajorityScale^2 distinct ids.
__global__ void majorityKernel(const int* __restrict__ carried, int input_width, DeviceImage level_points, int scale,
                               int* __restrict__ majority) {
  const std::size_t k = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const int w = level_points.width;
  if (k >= std::size_t(w) * level_points.height) return;
  const int x = int(k % std::size_t(w)), y = int(k / std::size_t(w));
  if (!isfinite(level_points.at(x, y, 2))) {
    majority[k] = -1;
    return;
  }
  constexpr int kCapacity = kMaxMajorityScale * kMaxMajorityScale;
  int ids[kCapacity], counts[kCapacity];
  const auto id_at = [&](int px, int py) { return carried[std::size_t(py) * input_width + px]; };
  majority[k] = warm_start_pixel::blockMajorityId(id_at, x, y, scale, ids, counts);
}

__global__ void idsOfLabelsKernel(const int* __restrict__ labels, const int* __restrict__ id_of_label,
                                  int motion_labels, std::size_t pixels, int* __restrict__ ids) {
  const std::size_t k = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (k >= pixels) return;
  const int label = labels[k];
  ids[k] = label >= 0 && label <= motion_labels ? id_of_label[label] : 0;
}

}  // namespace

void launchIdsOfLabels(const int* labels, const int* id_of_label, int motion_labels, std::size_t pixels, int* ids,
                       cudaStream_t stream) {
  if (pixels == 0) return;
  idsOfLabelsKernel<<<blocksFor(pixels), kThreads, 0, stream>>>(labels, id_of_label, motion_labels, pixels, ids);
  MCFLOW_CUDA_CHECK_LAUNCH("idsOfLabelsKernel");
}

void launchCarryIds(const int* ids, const float* optical_flow, const float* moved_depth, const float* depth, int width,
                    int height, double tolerance, unsigned long long* winner, int* carried, int* closed,
                    cudaStream_t stream) {
  const std::size_t pixels = std::size_t(width) * std::size_t(height);
  if (pixels == 0) return;
  // Every byte 0xff: kNoWinner.
  MCFLOW_CUDA_CHECK(cudaMemsetAsync(winner, 0xff, pixels * sizeof(unsigned long long), stream));
  splatKernel<<<blocksFor(pixels), kThreads, 0, stream>>>(ids, optical_flow, moved_depth, width, height, winner);
  MCFLOW_CUDA_CHECK_LAUNCH("splatKernel");
  keepKernel<<<blocksFor(pixels), kThreads, 0, stream>>>(winner, ids, depth, pixels, tolerance, carried);
  MCFLOW_CUDA_CHECK_LAUNCH("keepKernel");
  closeGapsKernel<<<blocksFor(pixels), kThreads, 0, stream>>>(carried, depth, width, height, tolerance, closed);
  MCFLOW_CUDA_CHECK_LAUNCH("closeGapsKernel");
}

void launchCarriedMajority(const int* carried, int input_width, const DeviceImage& level_points, int scale,
                           int* majority, cudaStream_t stream) {
  if (scale < 1 || scale > kMaxMajorityScale)
    throw InputError("CUDA carried labels: scale " + std::to_string(scale) + " outside [1, " +
                     std::to_string(kMaxMajorityScale) + "]");
  const std::size_t pixels = std::size_t(level_points.width) * std::size_t(level_points.height);
  if (pixels == 0) return;
  majorityKernel<<<blocksFor(pixels), kThreads, 0, stream>>>(carried, input_width, level_points, scale, majority);
  MCFLOW_CUDA_CHECK_LAUNCH("majorityKernel");
}

}  // namespace cuda_detail
}  // namespace mc_flow
