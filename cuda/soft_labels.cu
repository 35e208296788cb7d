// Soft-label operations of the device-resident solve (src/core/soft_labels.cpp, solve_backend.cpp's initialisation and
// the HostLabelStore of label_adaptation.cpp are the references): initial hard labels, resampling between
// pyramid levels, remapping planes (merges, removals), per-label supports and owned-pixel moments, cuts.
// Sums run in a fixed order (the chunked sums of device_stages.h), so repeated solves are bit-identical.
#include <cuda_runtime.h>

#include <cmath>
#include <cstdint>
#include <string>

#include "cuda_check.h"
#include "device_stages.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/soft_labels_pixel.h"

namespace mc_flow {
namespace cuda_detail {

namespace {

constexpr int kBlockX = 32, kBlockY = 8;
constexpr int kMaxRemapPlanes = 512;
constexpr int kMomentValues = 10;

dim3 gridFor(int width, int height) {
  return dim3(unsigned((width + kBlockX - 1) / kBlockX), unsigned((height + kBlockY - 1) / kBlockY));
}

__global__ void oneHotKernel(const DeviceImage points, const int* __restrict__ hard, int count, float* __restrict__ u) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= points.width || y >= points.height) return;
  const std::size_t plane = std::size_t(points.width) * points.height, idx = std::size_t(y) * points.width + x;
  const int h = hard[idx];
  const int label = (h >= 0 && isfinite(points.at(x, y, 2))) ? h : count - 1;
  for (int i = 0; i < count; ++i) u[i * plane + idx] = i == label ? 1.f : 0.f;
}

__global__ void allValidAsOneKernel(const DeviceImage points, float* __restrict__ u) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= points.width || y >= points.height) return;
  const std::size_t plane = std::size_t(points.width) * points.height, idx = std::size_t(y) * points.width + x;
  const bool valid = isfinite(points.at(x, y, 2));
  u[idx] = valid ? 1.f : 0.f;
  u[plane + idx] = valid ? 0.f : 1.f;
}

__global__ void downsampleKernel(const float* __restrict__ in, int w, int h, int count, float* __restrict__ out, int ow,
                                 int oh) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= ow || y >= oh) return;
  int x0, x1, y0, y1;
  soft_labels_pixel::downsampleSources(x, w, x0, x1);
  soft_labels_pixel::downsampleSources(y, h, y0, y1);
  const std::size_t plane = std::size_t(w) * h, out_plane = std::size_t(ow) * oh;
  for (int i = 0; i < count; ++i) {
    const float* src = in + i * plane;
    out[i * out_plane + std::size_t(y) * ow + x] =
        soft_labels_pixel::average4(src[std::size_t(y0) * w + x0], src[std::size_t(y0) * w + x1],
                                    src[std::size_t(y1) * w + x0], src[std::size_t(y1) * w + x1]);
  }
}

__global__ void upsampleKernel(const float* __restrict__ in, int w, int h, int count, float* __restrict__ out, int ow,
                               int oh, double ratio_x, double ratio_y) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= ow || y >= oh) return;
  int x0, x1, y0, y1;
  float ax, ay;
  soft_labels_pixel::upsampleTap(x, w, ratio_x, x0, x1, ax);
  soft_labels_pixel::upsampleTap(y, h, ratio_y, y0, y1, ay);
  const std::size_t plane = std::size_t(w) * h, out_plane = std::size_t(ow) * oh, o = std::size_t(y) * ow + x;
  float sum = 0.f;
  for (int i = 0; i < count; ++i) {
    const float* r0 = in + i * plane + std::size_t(y0) * w;
    const float* r1 = in + i * plane + std::size_t(y1) * w;
    const float v = soft_labels_pixel::interpolate(r0[x0], r0[x1], r1[x0], r1[x1], ax, ay);
    out[i * out_plane + o] = v;
    sum = __fadd_rn(sum, v);
  }
  // Renormalised as on the CPU; a pixel without mass goes to the outlier label.
  const float scale = soft_labels_pixel::renormalisation(sum);
  for (int i = 0; i < count; ++i) out[i * out_plane + o] = __fmul_rn(out[i * out_plane + o], scale);
  if (scale == 0.f) out[std::size_t(count - 1) * out_plane + o] = 1.f;
}

template <typename T>
__global__ void resampleMaskKernel(const T* __restrict__ in, int w, int h, T* __restrict__ out, int ow, int oh,
                                   double scale) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= ow || y >= oh) return;
  const int sy = min(max(int(floor((y + 0.5) * scale)), 0), h - 1);
  const int sx = min(max(int(floor((x + 0.5) * scale)), 0), w - 1);
  out[std::size_t(y) * ow + x] = in[std::size_t(sy) * w + sx];
}

struct RemapTable {
  int target[kMaxRemapPlanes];
};

__global__ void remapKernel(const float* __restrict__ in, std::size_t plane, int count, const RemapTable table,
                            int new_count, float* __restrict__ out) {
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  for (int j = 0; j < new_count; ++j) {
    float sum = 0.f;
    for (int i = 0; i < count; ++i)
      if (table.target[i] == j) sum = __fadd_rn(sum, in[i * plane + idx]);
    out[j * plane + idx] = sum;
  }
}

// The carried label a pixel started in: its hard initial label where that is one of the carried ones and the point is
// valid (the CPU backend's argmax of the one-hot labels), else -1.
__global__ void carriedFromHardKernel(const DeviceImage points, const int* __restrict__ hard, int carried_labels,
                                      int* __restrict__ carried) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const int h = hard[idx];
  carried[idx] = isfinite(points.data[idx * 3 + 2]) && h >= 0 && h < carried_labels ? h : -1;
}

__global__ void remapCarriedKernel(int* __restrict__ carried, std::size_t plane, const RemapTable table,
                                   int new_count) {
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const int c = carried[idx];
  if (c < 0) return;
  const int t = table.target[c];
  carried[idx] = t == new_count - 1 ? -1 : t;  // merged: the merged label; removed to the outlier label: none
}

__global__ void releaseCutPixelsKernel(const float* __restrict__ u, std::size_t plane, int first_new, int cut_count,
                                       int* __restrict__ carried) {
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  for (int c = 0; c < cut_count; ++c)
    if (u[std::size_t(first_new + c) * plane + idx] > 0.f) carried[idx] = -1;
}

// Pixel k's share of label `label`'s support: sum of u.
struct SupportPixel {
  const float* u;
  std::size_t plane;
  __device__ void operator()(int label, std::size_t k, double* sums) const { sums[0] += u[label * plane + k]; }
};

// Per motion label: count, sum P, sum P P^T (xx xy xz yy yz zz) of its owned pixels (u >= 0.5).
struct MomentPixel : LabelPlanesAndPoints {
  __device__ void operator()(int label, std::size_t k, double* m) const {
    const float z = points.data[k * 3 + 2];
    if (u[label * plane + k] < 0.5f || !isfinite(z)) return;
    const double P[3] = {points.data[k * 3], points.data[k * 3 + 1], z};
    m[0] += 1;
    m[1] += P[0];
    m[2] += P[1];
    m[3] += P[2];
    m[4] += P[0] * P[0];
    m[5] += P[0] * P[1];
    m[6] += P[0] * P[2];
    m[7] += P[1] * P[1];
    m[8] += P[1] * P[2];
    m[9] += P[2] * P[2];
  }
};

__global__ void cutKernel(const float* __restrict__ in, const DeviceImage points, int count,
                          const double* __restrict__ cuts, int cut_count, const float* __restrict__ cut_costs,
                          float* __restrict__ out, unsigned long long* __restrict__ moved) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const int motion = count - 1;
  for (int i = 0; i < motion; ++i) out[i * plane + idx] = in[i * plane + idx];
  for (int c = 0; c < cut_count; ++c) out[(motion + c) * plane + idx] = 0.f;
  out[std::size_t(motion + cut_count) * plane + idx] = in[std::size_t(motion) * plane + idx];
  const float z = points.data[idx * 3 + 2];
  if (!isfinite(z)) return;
  const double P[3] = {points.data[idx * 3], points.data[idx * 3 + 1], z};
  for (int c = 0; c < cut_count; ++c) {
    const double* cut = cuts + kCutValues * c;
    const int parent = int(cut[0]);
    float* from = out + std::size_t(parent) * plane + idx;
    if (*from < 0.5f) continue;
    if (cut[7] > 0) {  // by the data: the pixels that pay more than cut[7] under the cut's twist
      if (!(double(cut_costs[std::size_t(cut[8]) * plane + idx]) > cut[7])) continue;
    } else {
      const double side = (P[0] - cut[1]) * cut[4] + (P[1] - cut[2]) * cut[5] + (P[2] - cut[3]) * cut[6];
      if (side <= 0) continue;
    }
    out[std::size_t(motion + c) * plane + idx] = *from;
    *from = 0.f;
    atomicAdd(moved + c, 1ull);  // integer counts: the order does not matter
  }
}

struct AbsoluteChangePixel {
  const float* a;
  const float* b;
  __device__ void operator()(int, std::size_t k, double* sums) const { sums[0] += fabs(double(a[k]) - double(b[k])); }
};

// Source pixels per target pixel between two pyramid levels: a power of two (integer halving drops an odd
// last column/row, so the size ratio is not exact).
double levelScale(int from, int to) { return std::exp2(std::round(std::log2(double(from) / double(to)))); }

}  // namespace

void launchOneHotLabels(const DeviceImage& points, const int* hard, int count, float* u, cudaStream_t stream) {
  oneHotKernel<<<gridFor(points.width, points.height), dim3(kBlockX, kBlockY), 0, stream>>>(points, hard, count, u);
  MCFLOW_CUDA_CHECK_LAUNCH("oneHotKernel");
}

void launchAllValidAsOne(const DeviceImage& points, float* u, cudaStream_t stream) {
  allValidAsOneKernel<<<gridFor(points.width, points.height), dim3(kBlockX, kBlockY), 0, stream>>>(points, u);
  MCFLOW_CUDA_CHECK_LAUNCH("allValidAsOneKernel");
}

void launchDownsampleLabels(const float* in, int width, int height, int count, float* out, int out_width,
                            int out_height, cudaStream_t stream) {
  downsampleKernel<<<gridFor(out_width, out_height), dim3(kBlockX, kBlockY), 0, stream>>>(in, width, height, count, out,
                                                                                          out_width, out_height);
  MCFLOW_CUDA_CHECK_LAUNCH("downsampleKernel");
}

void launchUpsampleLabels(const float* in, int width, int height, int count, float* out, int out_width, int out_height,
                          cudaStream_t stream) {
  upsampleKernel<<<gridFor(out_width, out_height), dim3(kBlockX, kBlockY), 0, stream>>>(
      in, width, height, count, out, out_width, out_height, soft_labels_pixel::upsampleRatio(out_width, width),
      soft_labels_pixel::upsampleRatio(out_height, height));
  MCFLOW_CUDA_CHECK_LAUNCH("upsampleKernel");
}

void launchResampleMask(const std::uint8_t* in, int width, int height, std::uint8_t* out, int out_width, int out_height,
                        cudaStream_t stream) {
  resampleMaskKernel<<<gridFor(out_width, out_height), dim3(kBlockX, kBlockY), 0, stream>>>(
      in, width, height, out, out_width, out_height, levelScale(width, out_width));
  MCFLOW_CUDA_CHECK_LAUNCH("resampleMaskKernel");
}

void launchResampleMask(const int* in, int width, int height, int* out, int out_width, int out_height,
                        cudaStream_t stream) {
  resampleMaskKernel<<<gridFor(out_width, out_height), dim3(kBlockX, kBlockY), 0, stream>>>(
      in, width, height, out, out_width, out_height, levelScale(width, out_width));
  MCFLOW_CUDA_CHECK_LAUNCH("resampleMaskKernel");
}

void launchCarriedFromHard(const DeviceImage& points, const int* hard, int carried_labels, int* carried,
                           cudaStream_t stream) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  carriedFromHardKernel<<<unsigned((plane + 255) / 256), 256, 0, stream>>>(points, hard, carried_labels, carried);
  MCFLOW_CUDA_CHECK_LAUNCH("carriedFromHardKernel");
}

namespace {

// A remap's host targets as a kernel argument.
RemapTable remapTable(const int* target, int count, const char* what) {
  if (count > kMaxRemapPlanes)
    throw InputError(std::string(what) + ": " + std::to_string(count) + " planes, at most " +
                     std::to_string(kMaxRemapPlanes));
  RemapTable table{};
  for (int i = 0; i < count; ++i) table.target[i] = target[i];
  return table;
}

}  // namespace

void launchRemapCarried(int* carried, std::size_t plane, int count, const int* target, int new_count,
                        cudaStream_t stream) {
  const RemapTable table = remapTable(target, count, "CUDA carried-label remap");
  remapCarriedKernel<<<unsigned((plane + 255) / 256), 256, 0, stream>>>(carried, plane, table, new_count);
  MCFLOW_CUDA_CHECK_LAUNCH("remapCarriedKernel");
}

void launchReleaseCutPixels(const float* u, std::size_t plane, int first_new, int cut_count, int* carried,
                            cudaStream_t stream) {
  releaseCutPixelsKernel<<<unsigned((plane + 255) / 256), 256, 0, stream>>>(u, plane, first_new, cut_count, carried);
  MCFLOW_CUDA_CHECK_LAUNCH("releaseCutPixelsKernel");
}

void launchRemapLabels(const float* in, std::size_t plane, int count, const int* target, int new_count, float* out,
                       cudaStream_t stream) {
  const RemapTable table = remapTable(target, count, "CUDA label remap");
  remapKernel<<<unsigned((plane + 255) / 256), 256, 0, stream>>>(in, plane, count, table, new_count, out);
  MCFLOW_CUDA_CHECK_LAUNCH("remapKernel");
}

void launchLabelSupports(const float* u, std::size_t plane, int motion_labels, DeviceBuffer<double>& scratch,
                         double* out, cudaStream_t stream) {
  launchChunkSums<1>(SupportPixel{u, plane}, plane, motion_labels, scratch, out, stream, "label supports");
}

void launchOwnedMoments(const float* u, const DeviceImage& points, int motion_labels, DeviceBuffer<double>& scratch,
                        double* out, cudaStream_t stream) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  launchChunkSums<kMomentValues>(MomentPixel{{u, points, plane}}, plane, motion_labels, scratch, out, stream,
                                 "owned moments");
}

void launchCutLabels(const float* in, const DeviceImage& points, int count, const double* cuts, int cut_count,
                     const float* cut_costs, float* out, unsigned long long* moved, cudaStream_t stream) {
  unsigned long long* counts = moved;
  MCFLOW_CUDA_CHECK(cudaMemsetAsync(counts, 0, std::size_t(cut_count) * sizeof(unsigned long long), stream));
  const std::size_t plane = std::size_t(points.width) * points.height;
  cutKernel<<<unsigned((plane + 255) / 256), 256, 0, stream>>>(in, points, count, cuts, cut_count, cut_costs, out,
                                                               counts);
  MCFLOW_CUDA_CHECK_LAUNCH("cutKernel");
}

void launchAbsoluteChange(const float* a, const float* b, std::size_t values, DeviceBuffer<double>& scratch,
                          double* out, cudaStream_t stream) {
  launchChunkSums<1>(AbsoluteChangePixel{a, b}, values, 1, scratch, out, stream, "absolute label change");
}

}  // namespace cuda_detail
}  // namespace mc_flow
