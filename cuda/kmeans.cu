// K-means on the device (src/core/kmeans.cpp: kmeansPoints, and assignToNearestCentre at the label level).
//
// kmeansPoints runs at a coarse level (40x30 to 160x90 points for 320x240 to 1280x720 inputs), and a warm start's
// kmeansPointList over the label level's pixels no carried segment covers (a few hundred to some thousands): one block
// does all of it, so the level's points never come down and only the centres do. The per-point rules are
// nearest_centre.h's and the seeding's draws are the host's (kmeansSeedingDraws), so the centres are the host's except
// where a sum over points, which runs here in another order (a tree of per-thread partials instead of one serial
// chain), changes a double in its last bits: a mean can then differ from the host's by an ulp of a float, and a seeding
// draw that falls within that rounding of a running sum's step picks the neighbouring point.
//
// The assignment at the label level: the centres go in as a kernel argument, one thread per pixel.
#include <cuda_runtime.h>

#include <climits>
#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>

#include "cuda_check.h"
#include "device_stages.h"
#include "mc_flow/core/nearest_centre.h"

namespace mc_flow {
namespace cuda_detail {

namespace {

constexpr int kThreads = 256;
constexpr int kKMeansThreads = 1024;  // one block: 32 warps
constexpr int kKMeansWarps = kKMeansThreads / 32;
constexpr int kMaxCentres = KMeansCentres::kMax;

__global__ void nearestCentreKernel(const DeviceImage points, const KMeansCentres centres, int* __restrict__ hard) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const float x = points.data[idx * 3], y = points.data[idx * 3 + 1], z = points.data[idx * 3 + 2];
  hard[idx] = isfinite(x) && isfinite(y) && isfinite(z) ? nearestCentreIndex(x, y, z, centres.xyz, centres.count) : -1;
}

__device__ __forceinline__ bool validPoint(const float* p) {
  return isfinite(p[0]) && isfinite(p[1]) && isfinite(p[2]);
}

// Whether pixel i's point takes part: valid, and uncovered where a warm start's hard labels are given.
__device__ __forceinline__ bool clusteredPoint(const DeviceImage& image, const int* uncovered_hard, int i) {
  return (uncovered_hard == nullptr || uncovered_hard[i] < 0) && validPoint(image.data + 3 * i);
}

struct MinInt {
  __device__ __forceinline__ int operator()(int a, int b) const { return b < a ? b : a; }
};
struct MaxInt {
  __device__ __forceinline__ int operator()(int a, int b) const { return a < b ? b : a; }
};

struct KMeansShared {
  float centres[3 * kMaxCentres];
  double sums[3 * kMaxCentres];
  int members[kMaxCentres];
  int count;  // centres so far
  int stop;   // the Lloyd loop or the final assignment ends
};

// Every point's nearest centre (points in a stride over the block), then the clusters' sums and member counts: warp w
// sums clusters w, w + 32, ... over the points in a fixed order (lanes in a stride, then a shuffle tree), so the
// sums are the same on every run.
__device__ void assignAndSum(const float* points, int n, int* assignment, KMeansShared& s, bool with_sums) {
  for (int i = threadIdx.x; i < n; i += kKMeansThreads)
    assignment[i] = nearestCentreIndex(points[3 * i], points[3 * i + 1], points[3 * i + 2], s.centres, s.count);
  __syncthreads();
  const int warp = threadIdx.x >> 5, lane = threadIdx.x & 31;
  for (int c = warp; c < s.count; c += kKMeansWarps) {
    double x = 0, y = 0, z = 0;
    int members = 0;
    for (int i = lane; i < n; i += 32)
      if (assignment[i] == c) {
        ++members;
        if (with_sums) {
          x += double(points[3 * i]);
          y += double(points[3 * i + 1]);
          z += double(points[3 * i + 2]);
        }
      }
    members = warpSum(members);
    if (with_sums) {
      x = warpSum(x);
      y = warpSum(y);
      z = warpSum(z);
    }
    if (lane == 0) {
      s.members[c] = members;
      s.sums[3 * c] = x;
      s.sums[3 * c + 1] = y;
      s.sums[3 * c + 2] = z;
    }
  }
  __syncthreads();
}

__global__ void __launch_bounds__(kKMeansThreads)
    kmeansKernel(const DeviceImage image, const KMeansRun run, float* __restrict__ points,
                 double* __restrict__ distance, int* __restrict__ assignment, KMeansOutcome* __restrict__ outcome) {
  using IntScan = cub::BlockScan<int, kKMeansThreads>;
  using DoubleScan = cub::BlockScan<double, kKMeansThreads>;
  using IntReduce = cub::BlockReduce<int, kKMeansThreads>;
  __shared__ union {
    typename IntScan::TempStorage int_scan;
    typename DoubleScan::TempStorage double_scan;
    typename IntReduce::TempStorage int_reduce;
  } temp;
  __shared__ KMeansShared s;
  const int t = threadIdx.x;

  // The valid points in pixel order (collectValidPoints; the uncovered ones: kmeansPointList's list): thread t
  // compacts a contiguous run of pixels.
  const int plane = image.width * image.height;
  const int pixel_run = (plane + kKMeansThreads - 1) / kKMeansThreads;
  const int pixel_begin = min(plane, t * pixel_run), pixel_end = min(plane, pixel_begin + pixel_run);
  int valid = 0;
  for (int i = pixel_begin; i < pixel_end; ++i) valid += clusteredPoint(image, run.uncovered_hard, i) ? 1 : 0;
  int run_offset = 0, n = 0;
  IntScan(temp.int_scan).ExclusiveSum(valid, run_offset, n);
  int offset = run_offset;
  for (int i = pixel_begin; i < pixel_end; ++i)
    if (clusteredPoint(image, run.uncovered_hard, i)) {
      for (int k = 0; k < 3; ++k) points[3 * offset + k] = image.data[3 * i + k];
      ++offset;
    }
  if (n == 0) {  // uniform: n is the block's total
    for (int k = t; k < 3 * kMaxCentres; k += kKMeansThreads) outcome->centres.xyz[k] = 0.f;  // all of it comes down
    if (t == 0) {
      outcome->centres.count = 0;
      outcome->iterations = 0;
    }
    return;
  }
  __syncthreads();  // the compacted points (global memory) are visible to the whole block

  // k-means++ seeding (seedCentres). Thread t owns a contiguous run of points, so that the running sum of the
  // distances is the run's prefix (a block scan) plus its own serial sum, in point order as on the host.
  const int point_run = (n + kKMeansThreads - 1) / kKMeansThreads;
  const int begin = min(n, t * point_run), end = min(n, begin + point_run);
  if (t == 0) {
    const long long first = min((long long)(n - 1), (long long)(run.draws[0] * double(n)));
    for (int k = 0; k < 3; ++k) s.centres[k] = points[3 * first + k];
    s.count = 1;
  }
  __syncthreads();
  for (int i = begin; i < end; ++i)
    distance[i] = double(kmeansSquaredDistance(points[3 * i], points[3 * i + 1], points[3 * i + 2], s.centres));
  while (s.count < run.k) {  // s.count changes only between the barriers below
    double mine = 0;
    for (int i = begin; i < end; ++i) mine += distance[i];
    double prefix = 0, total = 0;
    DoubleScan(temp.double_scan).ExclusiveSum(mine, prefix, total);
    if (!(total > 0)) break;  // uniform: every remaining point coincides with a centre
    const double target = run.draws[s.count] * total;
    int crossing = INT_MAX, last_uncovered = -1;
    double running = prefix;
    for (int i = begin; i < end; ++i) {
      running += distance[i];
      if (running > target && distance[i] > 0) {
        crossing = i;
        break;
      }
    }
    for (int i = end - 1; i >= begin; --i)
      if (distance[i] > 0) {
        last_uncovered = i;
        break;
      }
    __syncthreads();  // temp is reused
    const int chosen = IntReduce(temp.int_reduce).Reduce(crossing, MinInt());
    __syncthreads();
    const int fallback = IntReduce(temp.int_reduce).Reduce(last_uncovered, MaxInt());
    if (t == 0) {
      const int c = chosen != INT_MAX ? chosen : fallback;  // rounding at the end of the scan: the last uncovered
      for (int k = 0; k < 3; ++k) s.centres[3 * s.count + k] = points[3 * c + k];
      ++s.count;
    }
    __syncthreads();
    const float* added = s.centres + 3 * (s.count - 1);
    for (int i = begin; i < end; ++i)
      distance[i] =
          fmin(distance[i], double(kmeansSquaredDistance(points[3 * i], points[3 * i + 1], points[3 * i + 2], added)));
  }

  // Lloyd iterations (assignAll + updateCentres): empty clusters are dropped, a drop counts as an infinite move.
  int iterations = 0;
  for (int it = 1; it <= run.max_iterations; ++it) {
    assignAndSum(points, n, assignment, s, true);
    if (t == 0) {
      double moved = 0;
      int kept = 0;
      for (int c = 0; c < s.count; ++c) {
        if (s.members[c] == 0) continue;
        const double count = double(s.members[c]);
        const float mean[3] = {float(s.sums[3 * c] / count), float(s.sums[3 * c + 1] / count),
                               float(s.sums[3 * c + 2] / count)};
        moved = fmax(moved, double(__fsqrt_rn(kmeansSquaredDistance(mean[0], mean[1], mean[2], s.centres + 3 * c))));
        for (int k = 0; k < 3; ++k) s.centres[3 * kept + k] = mean[k];  // kept <= c: never overwrites an unread centre
        ++kept;
      }
      if (kept != s.count) moved = INFINITY;
      s.count = kept;
      s.stop = moved <= run.tolerance_m ? 1 : 0;
    }
    iterations = it;
    __syncthreads();
    if (s.stop) break;
  }
  // The final assignment to the returned centres; a centre without points is dropped, until none is.
  for (;;) {
    assignAndSum(points, n, assignment, s, false);
    if (t == 0) {
      int kept = 0;
      for (int c = 0; c < s.count; ++c) {
        if (s.members[c] == 0) continue;
        for (int k = 0; k < 3; ++k) s.centres[3 * kept + k] = s.centres[3 * c + k];
        ++kept;
      }
      s.stop = kept == s.count ? 1 : 0;
      s.count = kept;
    }
    __syncthreads();
    if (s.stop) break;
  }
  // A warm start's uncovered pixels take their clusters (the final assignment's, to the centres returned).
  if (run.uncovered_hard != nullptr) {
    offset = run_offset;
    for (int i = pixel_begin; i < pixel_end; ++i)
      if (clusteredPoint(image, run.uncovered_hard, i)) run.uncovered_hard[i] = run.first_new + assignment[offset++];
  }
  for (int k = t; k < 3 * kMaxCentres; k += kKMeansThreads)  // the whole answer comes down: no byte left unwritten
    outcome->centres.xyz[k] = k < 3 * s.count ? s.centres[k] : 0.f;
  if (t == 0) {
    outcome->centres.count = s.count;
    outcome->iterations = iterations;
  }
}

}  // namespace

void launchNearestCentreLabels(const DeviceImage& points, const KMeansCentres& centres, int* hard,
                               cudaStream_t stream) {
  const std::size_t plane = std::size_t(points.width) * points.height;
  if (plane == 0) return;
  nearestCentreKernel<<<unsigned((plane + kThreads - 1) / kThreads), kThreads, 0, stream>>>(points, centres, hard);
  MCFLOW_CUDA_CHECK_LAUNCH("nearestCentreKernel");
}

void launchKMeans(const DeviceImage& points, const KMeansRun& run, float* scratch_points, double* scratch_distances,
                  int* scratch_assignment, KMeansOutcome* outcome, cudaStream_t stream) {
  kmeansKernel<<<1, kKMeansThreads, 0, stream>>>(points, run, scratch_points, scratch_distances, scratch_assignment,
                                                 outcome);
  MCFLOW_CUDA_CHECK_LAUNCH("kmeansKernel");
}

}  // namespace cuda_detail
}  // namespace mc_flow
