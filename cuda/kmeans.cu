// K-means' assignment at the label level on the device (src/core/kmeans.cpp: assignToNearestCentre): the
// centres (a few dozen, from K-means on the host at a coarse level) go in as a kernel argument, so the label
// level's points never come down. The rule is nearest_centre.h's, operation for operation: the same labels.
#include <cuda_runtime.h>

#include "cuda_check.h"
#include "device_stages.h"
#include "mc_flow/core/nearest_centre.h"

namespace mc_flow {
namespace cuda_detail {

namespace {

constexpr int kThreads = 256;

__global__ void nearestCentreKernel(const DeviceImage points, const KMeansCentres centres, int* __restrict__ hard) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const float x = points.data[idx * 3], y = points.data[idx * 3 + 1], z = points.data[idx * 3 + 2];
  hard[idx] = isfinite(x) && isfinite(y) && isfinite(z) ? nearestCentreIndex(x, y, z, centres.xyz, centres.count) : -1;
}

}  // namespace

void launchNearestCentreLabels(const DeviceImage& points, const KMeansCentres& centres, int* hard,
                               cudaStream_t stream) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  if (plane == 0) return;
  nearestCentreKernel<<<unsigned((plane + kThreads - 1) / kThreads), kThreads, 0, stream>>>(points, centres, hard);
  MCFLOW_CUDA_CHECK_LAUNCH("nearestCentreKernel");
}

}  // namespace cuda_detail
}  // namespace mc_flow
