// The device side of the solve's stages, for cuda/solve_backend.cu: each stage's .cu file (the same name as
// its CPU counterpart in src/core) exposes one launcher or engine here. Everything works on device pointers
// on the caller's stream; nothing here synchronises except where a function returns host numbers.
// Included by cuda/*.cu only.
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include "cuda_check.h"
#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/label_adaptation.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/scene_flow.h"
#include "mc_flow/core/scene_flow_pixel.h"
#include "mc_flow/core/se3_coefficients.h"
#include "sampling_device.cuh"

namespace mc_flow {
namespace cuda_detail {

/// @brief One pyramid level of both frames on the device (what the motion, label and occlusion stages read).
struct DeviceLevel {
  int width = 0, height = 0;
  Intrinsics intrinsics;
  DeviceImage points1, intensity1, intensity2, depth2, intensity_grad2, depth_grad2;
};

// ---------------------------------------------------------------- SE(3) in double (as src/core/se3.cpp)
__device__ __forceinline__ void skew3(const double w[3], double S[9]) {
  S[0] = 0;
  S[1] = -w[2];
  S[2] = w[1];
  S[3] = w[2];
  S[4] = 0;
  S[5] = -w[0];
  S[6] = -w[1];
  S[7] = w[0];
  S[8] = 0;
}

__device__ __forceinline__ void mul3(const double A[9], const double B[9], double C[9]) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) C[r * 3 + c] = A[r * 3] * B[c] + A[r * 3 + 1] * B[3 + c] + A[r * 3 + 2] * B[6 + c];
}

/// @brief The warp's total in lane 0 (a shuffle-down tree: a fixed order, so the same bits on every run); every lane
/// of the warp must take part.
template <typename T>
__device__ __forceinline__ T warpSum(T v) {
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_down_sync(0xffffffffu, v, offset);
  return v;
}

/// @brief A rigid motion as the per-pixel kernels use it: rows 0..2 of exp(xi) in float (row-major 3x4).
struct DeviceTransform {
  float m[12];
};
DeviceTransform deviceTransform(const Vector6d& twist);

// ---------------------------------------------------------------- per-label sums over many blocks
// A per-label sum over the pixels of a level used to run in one block per label (or one block in all), whose
// strided loop was latency-bound: 35-850 us per call on an H100 (ncu, 320x240). Now the pixels are cut into
// chunks, block (chunk, label) sums its chunk with a fixed tree and addChunksKernel adds the chunks in
// order: the same bits on every run, a few us per call.
constexpr int kChunkThreads = 256;
// Pixels per block: 4 per thread. The loop is latency-bound (each pixel's loads wait for the previous one's), so
// short chunks and many blocks: 16 per thread took ~10 us for one value per pixel (ncu, H100), 4 per thread a few.
constexpr std::size_t kChunkPixels = 4 * kChunkThreads;
constexpr std::size_t kMaxChunks = 1024;

inline std::size_t chunkCount(std::size_t pixels) {
  return std::max<std::size_t>(1, std::min(kMaxChunks, (pixels + kChunkPixels - 1) / kChunkPixels));
}

/// @brief Block (chunk, label): `pixel(label, k, sums)` adds pixel k's V values into `sums` for every k of the
/// chunk; the block's sums go to partials[(label * chunks + chunk) * V + v].
template <int V, class Pixel>
__global__ void __launch_bounds__(kChunkThreads)
    chunkSumsKernel(Pixel pixel, std::size_t pixels, std::size_t chunk_pixels, double* partials) {
  constexpr int kWarps = kChunkThreads / 32;
  __shared__ double warp_sums[kWarps * V];
  const int label = int(blockIdx.y);
  const std::size_t begin = std::size_t(blockIdx.x) * chunk_pixels;
  const std::size_t end = begin + chunk_pixels < pixels ? begin + chunk_pixels : pixels;
  double sums[V];
#pragma unroll
  for (int v = 0; v < V; ++v) sums[v] = 0.0;
  for (std::size_t k = begin + threadIdx.x; k < end; k += blockDim.x) pixel(label, k, sums);
  // A shuffle tree per warp, then the warps in order: fixed, so the same bits on every run.
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
#pragma unroll
  for (int v = 0; v < V; ++v) {
    double s = sums[v];
#pragma unroll
    for (int offset = 16; offset > 0; offset >>= 1) s += __shfl_down_sync(0xffffffffu, s, offset);
    if (lane == 0) warp_sums[warp * V + v] = s;
  }
  __syncthreads();
  for (int v = threadIdx.x; v < V; v += blockDim.x) {
    double s = 0.0;
    for (int w = 0; w < kWarps; ++w) s += warp_sums[w * V + v];
    partials[(std::size_t(label) * gridDim.x + blockIdx.x) * V + v] = s;
  }
}

/// @brief out[j] = sum over chunks c in order of partials[(j / V * chunks + c) * V + j % V], j < labels * V:
/// one warp per value, lane l adds chunks l, l + 32, ..., then a fixed shuffle tree.
template <int V>
__global__ void addChunksKernel(const double* __restrict__ partials, int chunks, int labels, double* __restrict__ out,
                                const int* skip = nullptr) {
  if (skip && *skip) return;  // a stopped device loop (motion_estimation.cu)
  const int value = int((std::size_t(blockIdx.x) * blockDim.x + threadIdx.x) >> 5);
  const int lane = threadIdx.x & 31;
  if (value >= labels * V) return;  // whole warps leave together
  const int label = value / V, v = value % V;
  double s = 0.0;
  for (int c = lane; c < chunks; c += 32) s += partials[(std::size_t(label) * chunks + c) * V + v];
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) s += __shfl_down_sync(0xffffffffu, s, offset);
  if (lane == 0) out[value] = s;
}

/// @brief What several per-label pixel functors of launchChunkSums read: the labels' planes (plane values each) and
/// frame 1's points.
struct LabelPlanesAndPoints {
  const float* u;
  DeviceImage points;
  std::size_t plane;
};

/// @brief Per label (labels of them), V sums over `pixels` pixels into out[label * V + v]; `partials` is grown to
/// the chunks' scratch. For the .cu files' launchers.
template <int V, class Pixel>
void launchChunkSums(Pixel pixel, std::size_t pixels, int labels, DeviceBuffer<double>& partials, double* out,
                     cudaStream_t stream, const char* what) {
  if (labels <= 0 || pixels == 0) return;
  const std::size_t chunks = chunkCount(pixels);
  partials.reserve(chunks * std::size_t(labels) * V);
  const std::size_t chunk_pixels = (pixels + chunks - 1) / chunks;
  chunkSumsKernel<V><<<dim3(unsigned(chunks), unsigned(labels)), kChunkThreads, 0, stream>>>(
      pixel, pixels, chunk_pixels, partials.get());
  kernel_launches.fetch_add(1, std::memory_order_relaxed);
  check(cudaGetLastError(), what, __FILE__, __LINE__);
  const unsigned warps_per_block = kChunkThreads / 32;
  const unsigned blocks = unsigned((std::size_t(labels) * V + warps_per_block - 1) / warps_per_block);
  addChunksKernel<V><<<blocks, kChunkThreads, 0, stream>>>(partials.get(), int(chunks), labels, out);
  kernel_launches.fetch_add(1, std::memory_order_relaxed);
  check(cudaGetLastError(), what, __FILE__, __LINE__);
}

/// @brief Frame 1's point P at pixel `idx` moved by its interpolated motion (scene_flow_pixel.h's warpPoint, which
/// src/core/scene_flow.cpp's warpPoints applies too), in double; `u` holds `plane` values per label, `motions` 18
/// doubles per motion label (packMotions of scene_flow.h).
__device__ __forceinline__ void warpPointDevice(const float P[3], const float* __restrict__ u, std::size_t plane,
                                                std::size_t idx, int motion_labels, const double* __restrict__ motions,
                                                double Q[3]) {
  Q[0] = P[0];
  Q[1] = P[1];
  Q[2] = P[2];
  if (motion_labels <= 0) return;
  scene_flow_pixel::MotionSums sums;
  for (int i = 0; i < motion_labels; ++i)
    scene_flow_pixel::addMotionLabel(sums, i, u[i * plane + idx], motions + scene_flow_pixel::kMotionValues * i);
  const auto largest = [&]() { return scene_flow_pixel::largestMotionLabel(u, plane, idx, motion_labels); };
  scene_flow_pixel::warpPoint(P, sums, motions, largest, Q);
}

// ---------------------------------------------------------------- pyramid (pyramid.cu)
/// @brief One frame's images at one pyramid level on the device; `points` or the gradients may be null (not
/// built). Level 0 holds the input intensity and raw depth before launchBuildPyramid.
struct DevicePyramidLevel {
  int width = 0, height = 0;
  Intrinsics intrinsics;
  float* intensity = nullptr;
  float* depth = nullptr;           // [m], 0 = invalid
  float* points = nullptr;          // 3 channels, NaN where depth is invalid
  float* intensity_grad = nullptr;  // 2 channels
  float* depth_grad = nullptr;      // 2 channels
};
/// @brief buildPyramid of one frame whose input sits in levels[0]: cleans the depth, then builds every coarser
/// level and each level's points and gradients where asked; `valid_counts` (one int per level, or null) gets the
/// valid pixels per level.
void launchBuildPyramid(const std::vector<DevicePyramidLevel>& levels, const Config& config, int* valid_counts,
                        cudaStream_t stream);

// ---------------------------------------------------------------- outputs (scene_flow.cu)
/// @brief The per-pixel outputs at level 0: pixels without a valid point go to the outlier label in `u` (in
/// place); every point is warped by its interpolated motion; scene flow (3 channels), optical flow (2), moved
/// depth and the argmax ids (1..m, 0 = outlier or no depth) are written; NaN where undefined.
void launchSceneFlowOutputs(const DeviceImage& points, float* u, int count, const double* motions, const Intrinsics& K,
                            float* scene_flow, float* optical_flow, float* moved_depth, int* ids, cudaStream_t stream);
/// @brief labelCentroids: per motion label the u-weighted sums of the valid points and of u (4 doubles:
/// x, y, z, weight), in a fixed order.
void launchLabelCentroidSums(const float* u, const DeviceImage& points, int motion_labels,
                             DeviceBuffer<double>& scratch, double* out, cudaStream_t stream);

// ---------------------------------------------------------------- stream mode (warm_start.cu)
/// @brief carryIds of warm_start.h on the device: `ids` (the previous pair's ids on its frame 1), its optical flow (2
/// channels) and moved depth, and this frame 1's cleaned level-0 `depth` (0 = none), all width x height; `winner` is
/// the splat's scratch (one per pixel), `carried` the kept ids before the gaps are closed, `closed` the answer.
void launchCarryIds(const int* ids, const float* optical_flow, const float* moved_depth, const float* depth, int width,
                    int height, double tolerance, unsigned long long* winner, int* carried, int* closed,
                    cudaStream_t stream);
/// @brief The previous result's ids from the backend's own output labels (`labels`: 0 or label index + 1, as the
/// outputs stage writes them): `ids` = id_of_label[labels] (id_of_label[0] = 0), 0 outside [0, motion_labels].
void launchIdsOfLabels(const int* labels, const int* id_of_label, int motion_labels, std::size_t pixels, int* ids,
                       cudaStream_t stream);
/// @brief The largest scale (input pixels per level pixel, per side) launchCarriedMajority takes.
constexpr int kMaxMajorityScale = 8;
/// @brief carriedLabelsAtLevel's majority ids on the device: per pixel of the level of `level_points`, -1 where it has
/// no point, else the id most of its scale x scale pixels of `carried` (input_width wide) hold when at least half of
/// them do, else 0. Throws InputError for a scale outside [1, kMaxMajorityScale].
void launchCarriedMajority(const int* carried, int input_width, const DeviceImage& level_points, int scale,
                           int* majority, cudaStream_t stream);

// ---------------------------------------------------------------- motion step (motion_estimation.cu)
/// @brief The motion step's accumulator on device-resident data (no uploads but the twists).
class DeviceMotionAccumulator : public MotionAccumulator {
 public:
  /// @brief Binds a level, its labels (count planes, the last the outlier) and an optional occlusion mask;
  /// the device memory must stay unchanged while accumulate() is used.
  virtual void bind(const DeviceLevel& level, const float* labels, int count, const std::uint8_t* occluded,
                    const Config& config) = 0;
  /// @brief refitUnions (label_adaptation.h) on the bound level and labels: every pass and step on the device, the
  /// batches (unionBatches) of a pass in one launch, one wait. The arguments are refitUnions' (checked there).
  virtual void refitUnions(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& groups,
                           const std::vector<int>& batches, const std::vector<Vector6d>& starts, int iterations,
                           const Config& config, std::vector<UnionFit>& fits) = 0;
  /// @brief refitPairsFromTheBetterMotion (label_adaptation.h) on the bound level and labels: the swapped pass, each
  /// pair's start (chosen on the device from `own_cost` and that pass's costs) and the refit, one wait. False (nothing
  /// done) when the batches exceed one pass: the host then chooses between passes. The arguments are checked there.
  virtual bool refitPairs(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& pairs,
                          const std::vector<int>& batches, const std::vector<double>& own_cost, int iterations,
                          const Config& config, std::vector<UnionFit>& fits) = 0;
  /// @brief accumulateLabelBlocks at each set of twists, the sets as batches of one launch, one wait.
  virtual void accumulateLabelBlockSets(const std::vector<std::vector<Vector6d>>& twist_sets,
                                        std::vector<MotionNormalEquations>& out) = 0;
};
std::unique_ptr<DeviceMotionAccumulator> makeDeviceMotionAccumulator(cudaStream_t stream);

// ---------------------------------------------------------------- label step (label_optimization.cu)
/// @brief The label problem on the device (see LabelProblem).
/// @brief The label step's problem on device buffers (aggregate: brace-initialised in member order).
struct DeviceLabelProblem {
  int width = 0, height = 0, count = 0;
  const float* data_cost = nullptr;
  const float* weight_x = nullptr;
  const float* weight_y = nullptr;
  const std::uint8_t* outlier_only = nullptr;
  Regularizer regularizer = Regularizer::Quadratic;
  double lambda = 1.0;
};

/// @brief The primal-dual iteration on device-resident u and p (see LabelOptimizer::optimize).
class DevicePrimalDual {
 public:
  virtual ~DevicePrimalDual() = default;
  virtual LabelStats run(const DeviceLabelProblem& problem, float* u, float* p, int iterations, double tolerance) = 0;
};
std::unique_ptr<DevicePrimalDual> makeDevicePrimalDual(cudaStream_t stream);

/// @brief geometricWeights of the level into weight_x / weight_y (one plane each).
void launchGeometricWeights(const DeviceLevel& level, double min_weight, float* weight_x, float* weight_y,
                            cudaStream_t stream);
/// @brief computeDataCosts: count = transforms + 1 planes of data costs and the outlier-only mask.
void launchDataCosts(const DeviceLevel& level, const DeviceTransform* transforms, int motion_labels,
                     const std::uint8_t* occluded, const Config& config, float* data_cost, std::uint8_t* outlier_only,
                     cudaStream_t stream);
/// @brief switchingEnergy without the cost factor: the sum of 1 - u_carried over the carried pixels with depth (`out`:
/// one double on the device).
void launchSwitchingShare(const float* u, const int* carried, const std::uint8_t* outlier_only, std::size_t plane,
                          DeviceBuffer<double>& scratch, double* out, cudaStream_t stream);
/// @brief Carried labels of the pixels a cut moved (u > 0 on planes first_new .. first_new + cut_count - 1) set to -1.
void launchReleaseCutPixels(const float* u, std::size_t plane, int first_new, int cut_count, int* carried,
                            cudaStream_t stream);
/// @brief addSwitchingCost: `cost` added to every label but the carried one where carried >= 0 and not outlier-only.
void launchAddSwitchingCost(const int* carried, float cost, std::size_t plane, int count,
                            const std::uint8_t* outlier_only, float* data_cost, cudaStream_t stream);

// ---------------------------------------------------------------- K-means' assignment (kmeans.cu)
/// @brief K-means centres as a kernel argument (Config::initial_labels is at most 64).
struct KMeansCentres {
  static constexpr int kMax = 64;
  float xyz[3 * kMax];
  int count = 0;
};
/// @brief Nearest centre (nearest_centre.h) of each valid point, -1 where the point is invalid.
void launchNearestCentreLabels(const DeviceImage& points, const KMeansCentres& centres, int* hard, cudaStream_t stream);
/// @brief What kmeansPoints is asked for, with its seeding's draws (kmeansSeedingDraws), as a kernel argument.
struct KMeansRun {
  double draws[KMeansCentres::kMax] = {};
  int k = 0;  ///< 1..KMeansCentres::kMax
  int max_iterations = 0;
  double tolerance_m = 0;
  /// Null: every valid point of the level. Else a warm start's hard labels at the level (device memory): only the
  /// valid points where they are -1 take part, and each such pixel's label becomes first_new + its cluster.
  int* uncovered_hard = nullptr;
  int first_new = 0;
};
/// @brief K-means' answer: the centres (count 0 when no point is valid) and the Lloyd iterations run.
struct KMeansOutcome {
  KMeansCentres centres;
  int iterations = 0;
};
/// @brief kmeansPoints on the valid points of `points` in one block on the device (kmeansPointList on the uncovered
/// ones with run.uncovered_hard, whose labels it then writes): `scratch_points` (3 floats per pixel),
/// `scratch_distances` (a double per pixel) and `scratch_assignment` (an int per pixel) hold the level's points, the
/// seeding's distances and the clusters; the answer goes to `outcome` (device memory).
void launchKMeans(const DeviceImage& points, const KMeansRun& run, float* scratch_points, double* scratch_distances,
                  int* scratch_assignment, KMeansOutcome* outcome, cudaStream_t stream);

// ---------------------------------------------------------------- soft labels (soft_labels.cu)
/// @brief `count` planes of one-hot labels from hard labels (-1 = outlier, the last plane); pixels without a
/// valid point go to the outlier plane.
void launchOneHotLabels(const DeviceImage& points, const int* hard, int count, float* u, cudaStream_t stream);
/// @brief Two planes: 1 on plane 0 where the point is valid, else on plane 1.
void launchAllValidAsOne(const DeviceImage& points, float* u, cudaStream_t stream);
/// @brief downsampleLabels: 2x2 means (clamped) of `count` planes.
void launchDownsampleLabels(const float* in, int width, int height, int count, float* out, int out_width,
                            int out_height, cudaStream_t stream);
/// @brief upsampleLabels: pixel-centre aligned bilinear, renormalised, empty pixels to the outlier label.
void launchUpsampleLabels(const float* in, int width, int height, int count, float* out, int out_width, int out_height,
                          cudaStream_t stream);
/// @brief Nearest-pixel resampling of a mask between pyramid levels.
void launchResampleMask(const std::uint8_t* in, int width, int height, std::uint8_t* out, int out_width, int out_height,
                        cudaStream_t stream);
void launchResampleMask(const int* in, int width, int height, int* out, int out_width, int out_height,
                        cudaStream_t stream);
/// @brief SolveBackend::holdCarriedLabels: the hard initial label where it is below `carried_labels` and the point
/// is valid, else -1.
void launchCarriedFromHard(const DeviceImage& points, const int* hard, int carried_labels, int* carried,
                           cudaStream_t stream);
/// @brief Carried labels through a remap (host `target`, count entries): target[c], or -1 where that is the outlier.
void launchRemapCarried(int* carried, std::size_t plane, int count, const int* target, int new_count,
                        cudaStream_t stream);
/// @brief out plane j = sum of the in planes i with target[i] == j, in ascending i (target on the device).
void launchRemapLabels(const float* in, std::size_t plane, int count, const int* target, int new_count, float* out,
                       cudaStream_t stream);
/// @brief Per motion label of `u` (count planes): sum of u (double), in a fixed order (`scratch`: the chunked
/// sums' partials, grown as needed).
void launchLabelSupports(const float* u, std::size_t plane, int motion_labels, DeviceBuffer<double>& scratch,
                         double* out, cudaStream_t stream);
/// @brief Per motion label: owned-pixel moments, 10 doubles (count, sum xyz, sum xx xy xz yy yz zz).
void launchOwnedMoments(const float* u, const DeviceImage& points, int motion_labels, DeviceBuffer<double>& scratch,
                        double* out, cudaStream_t stream);
/// @brief Cuts (parent, centre xyz, axis xyz, cost_above, cost plane as doubles; kCutValues each) appended as planes
/// [motion_labels, motion_labels + cuts) of `out` (count + cuts planes); counts the moved pixels per cut. A cut with
/// cost_above > 0 moves the parent's pixels whose value in plane `cost plane` of `cut_costs` exceeds it (LabelCut).
constexpr int kCutValues = 9;
void launchCutLabels(const float* in, const DeviceImage& points, int count, const double* cuts, int cut_count,
                     const float* cut_costs, float* out, unsigned long long* moved, cudaStream_t stream);
/// @brief Sum over planes of |a - b| per pixel, added into one double (fixed order).
void launchAbsoluteChange(const float* a, const float* b, std::size_t values, DeviceBuffer<double>& scratch,
                          double* out, cudaStream_t stream);

// ---------------------------------------------------------------- occlusion (occlusion.cu)
/// @brief detectOcclusions(warpPoints(points, u, twists), depth2, K) at one level into `occluded`.
/// `motions` holds 18 doubles per motion label (the twist, then rows 0..2 of its exp); `counts` (one int per
/// pixel) and `targets` (one per pixel) are scratch.
void launchOcclusion(const DeviceLevel& level, const float* u, int count, const double* motions, const Config& config,
                     int* counts, long long* targets, float* warped_z, std::uint8_t* occluded, cudaStream_t stream);

}  // namespace cuda_detail
}  // namespace mc_flow
