// The outputs of the device-resident solve at the input resolution (src/core/scene_flow.cpp and the CPU
// backend's outputs() are the reference): the interpolated motion per pixel, scene and optical flow, moved depth,
// argmax ids and the per-label centroid sums, so that the results come down in one transfer.
#include <cuda_runtime.h>

#include <vector>

#include "cuda_check.h"
#include "device_stages.h"
#include "mc_flow/core/se3.h"

namespace mc_flow {
namespace cuda_detail {

namespace {

constexpr int kThreads = 256;
constexpr int kCentroidValues = 4;

__global__ void outputsKernel(const DeviceImage points, float* __restrict__ u, int count,
                              const double* __restrict__ motions, Intrinsics K, float* __restrict__ scene_flow,
                              float* __restrict__ optical_flow, float* __restrict__ moved_depth,
                              int* __restrict__ ids) {
  const int W = points.width, H = points.height;
  const std::size_t plane = std::size_t(W) * H;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const int x = int(idx % std::size_t(W)), y = int(idx / std::size_t(W));
  const float nan = __int_as_float(0x7fc00000);
  const float P[3] = {points.at(x, y, 0), points.at(x, y, 1), points.at(x, y, 2)};
  const int outlier = count - 1;
  if (!(isfinite(P[0]) && isfinite(P[1]) && isfinite(P[2]))) {
    // Pixels without depth belong to the outlier label whatever the upsampling blended in.
    for (int i = 0; i < count; ++i) u[i * plane + idx] = i == outlier ? 1.f : 0.f;
    for (int c = 0; c < 3; ++c) scene_flow[3 * idx + c] = nan;
    optical_flow[2 * idx] = optical_flow[2 * idx + 1] = nan;
    moved_depth[idx] = nan;
    ids[idx] = 0;
    return;
  }
  double Qd[3];
  warpPointDevice(P, u, plane, idx, count - 1, motions, Qd);
  const float Q[3] = {float(Qd[0]), float(Qd[1]), float(Qd[2])};
  moved_depth[idx] = Q[2];
  const bool moved_finite = isfinite(Q[0]) && isfinite(Q[1]) && isfinite(Q[2]);
  for (int c = 0; c < 3; ++c) scene_flow[3 * idx + c] = moved_finite ? __fsub_rn(Q[c], P[c]) : nan;
  float flow[2];
  if (moved_finite && scene_flow_pixel::opticalFlow(Q, K.fx, K.fy, K.cx, K.cy, x, y, flow)) {
    optical_flow[2 * idx] = flow[0];
    optical_flow[2 * idx + 1] = flow[1];
  } else {
    optical_flow[2 * idx] = optical_flow[2 * idx + 1] = nan;
  }
  int best = 0;  // strict: ties keep the lower label index (SoftLabels::argmax)
  for (int i = 1; i < count; ++i)
    if (u[i * plane + idx] > u[best * plane + idx]) best = i;
  ids[idx] = best == outlier ? 0 : best + 1;
}

// Pixel k's share of a motion label's centroid sums: u-weighted x, y, z of the valid points, and u.
struct CentroidPixel : LabelPlanesAndPoints {
  __device__ void operator()(int label, std::size_t k, double* m) const {
    const float z = points.data[k * 3 + 2];
    const double w = u[label * plane + k];
    if (w <= 0 || !isfinite(z)) return;
    m[0] += w * points.data[k * 3];
    m[1] += w * points.data[k * 3 + 1];
    m[2] += w * z;
    m[3] += w;
  }
};

}  // namespace

void launchSceneFlowOutputs(const DeviceImage& points, float* u, int count, const double* motions, const Intrinsics& K,
                            float* scene_flow, float* optical_flow, float* moved_depth, int* ids, cudaStream_t stream) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  outputsKernel<<<unsigned((plane + kThreads - 1) / kThreads), kThreads, 0, stream>>>(
      points, u, count, motions, K, scene_flow, optical_flow, moved_depth, ids);
  MCFLOW_CUDA_CHECK_LAUNCH("outputsKernel");
}

void launchLabelCentroidSums(const float* u, const DeviceImage& points, int motion_labels,
                             DeviceBuffer<double>& scratch, double* out, cudaStream_t stream) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  launchChunkSums<kCentroidValues>(CentroidPixel{{u, points, plane}}, plane, motion_labels, scratch, out, stream,
                                   "label centroid sums");
}

}  // namespace cuda_detail
}  // namespace mc_flow
