// Motion step's normal equations on the GPU: the per-pixel part of CpuMotionAccumulator
// (src/core/motion_estimation.cpp, the reference), one thread per pixel; each warp's 32 values of H and g are
// added in float, everything beyond the warp in double.
//
// Arithmetic. The per-pixel rules are motion_estimation_pixel.h's, shared with the CPU: warping, projection, the
// in-view test, the bilinear samples (sampling.h) and the residuals use explicitly rounded float operations in the
// CPU's order, so every discrete decision (in view, depth jump, active labels) is the CPU's. The Jacobians and the
// per-pixel 6x6 products may be contracted into FMAs (a few float ulps per pixel) and the sums run in another order
// than the CPU's, so the results agree with the CPU to a relative ~1e-7, not bit for bit
// (test/cuda/test_motion_estimation_cuda.cpp states the tolerances).
//
// Reduction (deterministic: the same sums in the same order on every run, as the CPU's static schedule
// gives; the Solver's results must not depend on scheduling). A pixel adds to the diagonal block, the
// gradient, the cost and the weighted pixel count of each of its active labels (29 values per label, the
// upper triangle of the symmetric 6x6 block only), and, when it has several active labels, to the
// off-diagonal blocks of each label pair (symmetric too: 21 values).
//  - Per label: each warp walks the labels present in it in ascending order and reduces the contributions
//    of the lanes holding the current label with shuffles into its own region of shared memory (all warps at
//    once; where the regions of eight warps do not fit, warps share a region and take turns); the regions
//    are added in warp order, each block writes its sums to its own slot, and a second kernel adds the slots
//    in block order (one warp per value, fixed lane partition, shuffle tree).
//  - Label pairs (blended pixels only): the per-pixel kernel stores the mass-weighted 6x6 upper triangle of
//    the blended pixels and flags them; block (chunk, pair) of the pair kernel sums w_a w_b times it over the
//    flagged pixels of its chunk of the level, and the chunks are added in order.
#include <cuda_runtime.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cuda_check.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/motion_estimation_pixel.h"
#include "mc_flow/core/motion_step_control.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/union_refit_step.h"
#include "device_stages.h"
#include "sampling_device.cuh"

namespace mc_flow {

namespace {

using cuda_detail::DeviceBuffer;
using cuda_detail::DeviceImage;
using cuda_detail::PinnedBuffer;

constexpr int kMaxMotionLabels = 128;  // as the CUDA label step's kMaxLabels; Config allows 64 (max_labels)
constexpr int kThreads = 256;          // one pixel per thread; warps span consecutive pixels of a row
constexpr int kWarps = kThreads / 32;

// Per-label sums: the 21 upper-triangle values of the diagonal H block (row-major, r <= c), g (6),
// label_cost, label_pixels.
constexpr int kUpper = 21;
constexpr int kLabelStride = kUpper + 6 + 2;
constexpr int kPairChunkPixels = 4 * kThreads;  // pixels per block of accumulatePairs: 4 per thread
constexpr long long kPairBlocks = 16384;        // accumulatePairs' grid: above this, several pairs per block
constexpr int kLabelMaskWords = (kMaxMotionLabels + 63) / 64;
constexpr int kLabelCost = kUpper + 6, kLabelPixels = kUpper + 7;
// Device memory for the block partials of one launch of batched passes (the merge test's pairs): 64 MiB holds about 95
// batches of 10 labels at 320x240, 17 of 13 labels at 640x480; more batches run in several launches.
constexpr std::size_t kBatchPartialBytes = std::size_t(64) << 20;

/// One staging buffer carved into consecutive arrays, each on a 16-byte boundary: one copy moves them all up, and a run
/// of adjacent arrays comes down in one copy (from an array's offset to the end).
class StagingLayout {
 public:
  /// Room for `count` values of T after the arrays so far; returns its offset [bytes].
  template <typename T>
  std::size_t add(std::size_t count) {
    const std::size_t offset = (bytes_ + 15) / 16 * 16;
    bytes_ = offset + count * sizeof(T);
    return offset;
  }
  std::size_t bytes() const { return bytes_; }
  /// The array at `offset` in a host or device copy of the buffer.
  template <typename T>
  static T* at(unsigned char* base, std::size_t offset) {
    return reinterpret_cast<T*>(base + offset);
  }

 private:
  std::size_t bytes_ = 0;
};

/// One motion label's linearisation point as the CPU uses it: the transform and left Jacobian in float
/// (row-major), the twist in double (blended pixels mix twists before their exp).
struct LabelMotion {
  float transform[12];
  float left_jacobian[36];
  double twist[6];
};

struct KernelParams {
  DeviceImage points1, intensity1, intensity2, depth2, intensity_grad2, depth_grad2;
  const float* labels = nullptr;           // n + 1 planes, the last one the outlier label
  const std::uint8_t* occluded = nullptr;  // may be null
  const LabelMotion* motions = nullptr;
  int width = 0, height = 0, motion_labels = 0;
  int sum_regions = kWarps;  // shared-memory regions of the per-label sums (a divisor of kWarps)
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float c_intensity = 0, c_depth = 0, depth_noise_reference = 0, alpha = 0, min_weight = 0;
  double out_of_view_cost = 0;
  double* block_partials = nullptr;  // per block: motion_labels * kLabelStride label sums, then cost, pixels
  std::uint8_t* blended = nullptr;   // per pixel: 1 when in view with several active labels
  // Per chunk of kPairChunkPixels pixels, kLabelMaskWords words: bit i set when a blended pixel of the chunk has
  // label i active (atomicOr: the same bits whatever the order), so a pair block skips chunks without both labels.
  unsigned long long* chunk_labels = nullptr;
  float* blended_hessian = nullptr;  // kUpper planes: mass * Hp of the blended pixels
  float* active_mass = nullptr;      // per pixel: sum of the active labels' weights (blended pixels)
  float* mass = nullptr;             // per pixel: motion-label mass (blended pixels)
  // The device IRLS loop's stop flag (null outside it): once a level's loop has stopped, the kernels still
  // queued for its remaining iterations return at once.
  const int* skip = nullptr;
  // False for a cost model's pass (accumulateLabelBlocks): the per-label sums only, no blended pixels stored for
  // the label pairs' kernel, no chunk masks. Such passes may be batched: blockIdx.y is the batch, its motions are
  // motions + batch * motion_labels and its block partials follow the previous batch's.
  bool label_pairs = true;
};

// ----------------------------------------------------------------- SE(3) in double (as src/core/se3.cpp)
using cuda_detail::mul3;
using cuda_detail::skew3;

// Rows 0..2 of exp(xi), cast to float (row-major 3x4).
__device__ void se3ExpDevice(const double xi[6], float T[12]) {
  double Td[12];
  se3ExpRows(xi, Td);
  for (int k = 0; k < 12; ++k) T[k] = float(Td[k]);
}

// Left Jacobian of SE(3) (se3_coefficients.h), cast to float (row-major 6x6). Q's seven 3x3 products are written with
// the skew identities FP = rho phi^T - (phi.rho) I, FPF = -(phi.rho) F, F^2 P + P F^2 = phi (phi x rho)^T - (phi x rho)
// phi^T - 2 |phi|^2 P and FPF^2 = F^2 PF = -(phi.rho) F^2: the same matrix in double (the last bits of a few entries
// differ, below what the cast to float keeps) in a quarter of the double-precision operations, which a blended pixel
// pays (docs/decisions/0009).
__device__ void se3LeftJacobianDevice(const double xi[6], float J[36]) {
  const double* rho = xi;
  const double* phi = xi + 3;
  double F[9], F2[9], P[9];
  skew3(phi, F);
  mul3(F, F, F2);
  skew3(rho, P);
  const double t2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2];
  double a, b, c, d;
  se3LeftJacobianCoefficients(t2, a, b, c, d);
  const double phi_dot_rho = phi[0] * rho[0] + phi[1] * rho[1] + phi[2] * rho[2];
  const double cross[3] = {phi[1] * rho[2] - phi[2] * rho[1], phi[2] * rho[0] - phi[0] * rho[2],
                           phi[0] * rho[1] - phi[1] * rho[0]};
  for (int k = 0; k < 36; ++k) J[k] = 0.f;
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) {
      const int e = r * 3 + col;
      const double identity = r == col ? 1.0 : 0.0;
      const float so3 = float(identity + a * F[e] + b * F2[e]);
      const double fp_pf = rho[r] * phi[col] + phi[r] * rho[col] - 2.0 * phi_dot_rho * identity;  // FP + PF
      const double f2p_pf2 = phi[r] * cross[col] - cross[r] * phi[col] - 2.0 * t2 * P[e];         // F^2 P + P F^2
      const double fpf = -phi_dot_rho * F[e];
      const double q = 0.5 * P[e] + b * (fp_pf + fpf) + c * (f2p_pf2 - 3.0 * fpf) + d * (-2.0 * phi_dot_rho * F2[e]);
      J[r * 6 + col] = so3;
      J[(r + 3) * 6 + col + 3] = so3;
      J[r * 6 + col + 3] = float(q);
    }
  }
}

// ----------------------------------------------------------------- per-pixel linearisation
// The rules are motion_estimation_pixel.h's, shared with the CPU accumulator.

// Motion-label weight of label i at a pixel: u_i / mass, kept when >= min_weight (the CPU's first pass).
__device__ __forceinline__ float rawWeight(const KernelParams& p, std::size_t plane, std::size_t idx, int i,
                                           float mass) {
  return motion_pixel::labelShare(__ldg(p.labels + i * plane + idx), mass);
}

// The warp's total in every lane (an xor butterfly: lanes i and i^offset add the same two values, so all lanes end
// with the same bits).
__device__ __forceinline__ float warpAllSum(float v) {
#pragma unroll
  for (int offset = 16; offset > 0; offset >>= 1) v += __shfl_xor_sync(0xffffffffu, v, offset);
  return v;
}

using cuda_detail::warpSum;

// Three blocks per SM (at most 80 registers, a few spilled): a 320x240 level's 300 blocks then run in one wave instead
// of 1.14 (128 registers, two blocks per SM); 320x240 solves took 11.8-12.2 ms against 13.2-13.7 ms (H100, same run).
__global__ void __launch_bounds__(kThreads, 3) accumulateNormalEquations(const KernelParams p) {
  if (p.skip && *p.skip) return;
  // sum_regions regions of block_values each: motion_labels * kLabelStride, then cost, pixels
  extern __shared__ double block_sums[];
  const int n = p.motion_labels;
  const int block_values = n * kLabelStride + 2;
  const int regions = p.sum_regions;
  const LabelMotion* motions = p.motions + std::size_t(blockIdx.y) * std::size_t(n);
  for (int k = threadIdx.x; k < regions * block_values; k += blockDim.x) block_sums[k] = 0.0;
  __syncthreads();

  const std::size_t plane = std::size_t(p.width) * p.height;
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const int lane = threadIdx.x & 31;

  // Per-pixel state; a lane without a usable pixel keeps valid = false and joins the warp reductions with zeros.
  bool valid = false, in_view = false;
  unsigned long long active_labels[kLabelMaskWords] = {};  // the pixel's active labels, one bit each
  float mass = 0.f, active_mass = 0.f;
  int first = n, n_active = 0;
  float Hm[kUpper];  // mass * Hp, upper triangle
  float gm[6];       // mass * gp
  double cost = 0.0;
#pragma unroll
  for (int k = 0; k < kUpper; ++k) Hm[k] = 0.f;
#pragma unroll
  for (int k = 0; k < 6; ++k) gm[k] = 0.f;

  if (idx < plane) {
    const int x = int(idx % std::size_t(p.width)), y = int(idx / std::size_t(p.width));
    const float P[3] = {p.points1.at(x, y, 0), p.points1.at(x, y, 1), p.points1.at(x, y, 2)};
    const bool occluded = p.occluded && p.occluded[idx];
    if (isfinite(P[2]) && !occluded) {
      for (int i = 0; i < n; ++i) mass = addRn(mass, __ldg(p.labels + i * plane + idx));
      if (motion_pixel::usableMass(mass)) {
        for (int i = 0; i < n; ++i) {
          const float w = rawWeight(p, plane, idx, i, mass);
          if (w >= p.min_weight) {
            if (n_active == 0) first = i;
            active_labels[i / 64] |= 1ull << (i % 64);
            active_mass = addRn(active_mass, w);
            ++n_active;
          }
        }
      }
    }
    if (n_active > 0) {
      valid = true;
      float T[12];
      float J[36];
      const float* transform = T;
      const float* left_jacobian = J;
      if (n_active > 1) {
        double xi_bar[6] = {0, 0, 0, 0, 0, 0};
        for (int word = 0; word < kLabelMaskWords; ++word)
          for (unsigned long long bits = active_labels[word]; bits != 0ull; bits &= bits - 1ull) {
            const int i = word * 64 + __ffsll(static_cast<long long>(bits)) - 1;
            const double w = double(divRn(rawWeight(p, plane, idx, i, mass), active_mass));
            for (int k = 0; k < 6; ++k) xi_bar[k] += w * motions[i].twist[k];
          }
        se3ExpDevice(xi_bar, T);
        se3LeftJacobianDevice(xi_bar, J);
      } else {
        transform = motions[first].transform;
        left_jacobian = motions[first].left_jacobian;
      }
      float P2[3];
      transformPoint(transform, P, P2);
      motion_pixel::Projection proj;
      float I2 = 0.f;
      in_view = motion_pixel::project(P2, p.fx, p.fy, p.cx, p.cy, p.width, p.height, proj) &&
                cuda_detail::sampleBilinearDevice(p.intensity2, proj.u, proj.v, 0, I2);
      if (in_view) {
        const float u = proj.u, v = proj.v;
        float gIx = 0.f, gIy = 0.f;
        cuda_detail::sampleBilinearDevice(p.intensity_grad2, u, v, 0, gIx);
        cuda_detail::sampleBilinearDevice(p.intensity_grad2, u, v, 1, gIy);
        const float rI = subRn(p.intensity1.at(x, y, 0), I2);
        float row[3], JI[6];
        motion_pixel::intensityRow(proj, gIx, gIy, row);
        motion_pixel::residualJacobian(P2, row, left_jacobian, JI);
        const float wI = motion_pixel::cauchyWeight(1.f, p.c_intensity, rI);
        const float wrI = wI * rI;
        float wJI[6];
#pragma unroll
        for (int i = 0; i < 6; ++i) {
          wJI[i] = wI * JI[i];
          gm[i] = wrI * JI[i];
        }
        {
          int k = 0;
#pragma unroll
          for (int r = 0; r < 6; ++r)
#pragma unroll
            for (int c = r; c < 6; ++c) Hm[k++] = wJI[r] * JI[c];
        }
        cost = motion_pixel::cauchyCost(p.c_intensity, rI);

        float Z2 = 0.f;
        if (cuda_detail::sampleDepthBilinearSmoothDevice(p.depth2, u, v, motion_pixel::kDepthEdgeJump, Z2)) {
          float gZx = 0.f, gZy = 0.f;
          cuda_detail::sampleBilinearDevice(p.depth_grad2, u, v, 0, gZx);
          cuda_detail::sampleBilinearDevice(p.depth_grad2, u, v, 1, gZy);
          const float rZ = subRn(P2[2], Z2);
          float JZ[6];
          motion_pixel::depthRow(proj, gZx, gZy, row);
          motion_pixel::residualJacobian(P2, row, left_jacobian, JZ);
          const float c_depth = motion_pixel::depthCauchyScale(p.c_depth, p.depth_noise_reference, Z2);
          const float wZ = motion_pixel::cauchyWeight(p.alpha, c_depth, rZ);
          const float wrZ = wZ * rZ;
          float wJZ[6];
#pragma unroll
          for (int i = 0; i < 6; ++i) {
            wJZ[i] = wZ * JZ[i];
            gm[i] += wrZ * JZ[i];
          }
          int k = 0;
#pragma unroll
          for (int r = 0; r < 6; ++r)
#pragma unroll
            for (int c = r; c < 6; ++c) Hm[k++] += wJZ[r] * JZ[c];
          cost += mulRn(p.alpha, motion_pixel::cauchyCost(c_depth, rZ));
        } else {
          cost += motion_pixel::missingDepthCost(p.alpha);
        }
#pragma unroll
        for (int k = 0; k < kUpper; ++k) Hm[k] = mulRn(mass, Hm[k]);
#pragma unroll
        for (int k = 0; k < 6; ++k) gm[k] = mulRn(mass, gm[k]);

        // Off-diagonal blocks of the label pairs: summed by accumulatePairs from these.
        if (p.label_pairs && n_active > 1) {
#pragma unroll
          for (int k = 0; k < kUpper; ++k) p.blended_hessian[k * plane + idx] = Hm[k];
          p.active_mass[idx] = active_mass;
          p.mass[idx] = mass;
        }
      }
    }
    if (p.label_pairs) p.blended[idx] = in_view && n_active > 1 ? 1 : 0;
  }
  // The chunk's label mask: one atomicOr per warp and word (a warp's 32 pixels lie in one chunk; OR is
  // order-independent, so the mask is the same on every run).
  const bool blended = in_view && n_active > 1;
  for (int w = 0; w < kLabelMaskWords && p.label_pairs; ++w) {  // label_pairs is uniform: whole warps shuffle
    unsigned long long bits = blended ? active_labels[w] : 0ull;
#pragma unroll
    for (int offset = 16; offset > 0; offset >>= 1) bits |= __shfl_xor_sync(0xffffffffu, bits, offset);
    if ((threadIdx.x & 31) == 0 && bits != 0ull)
      atomicOr(p.chunk_labels + (std::size_t(blockIdx.x) * blockDim.x / kPairChunkPixels) * kLabelMaskWords + w, bits);
  }

  // Pixel totals (every lane takes part in the shuffles).
  const double total_cost = warpSum(!valid ? 0.0 : in_view ? double(mass) * cost : double(mass) * p.out_of_view_cost);
  const double total_pixels = warpSum(in_view ? 1.0 : 0.0);

  // Per-label sums: each warp into its region; warps sharing a region take turns (a fixed order of the
  // shared-memory additions). A warp visits the labels its lanes hold, in ascending order.
  const int warp = threadIdx.x >> 5;
  double* region = block_sums + (warp % regions) * block_values;
  for (int turn = 0; turn < kWarps / regions; ++turn) {
    if (warp / regions == turn) {  // warp-uniform: whole warps enter, so the shuffles see all 32 lanes
      if (lane == 0) {
        region[n * kLabelStride] += total_cost;
        region[n * kLabelStride + 1] += total_pixels;
      }
      // The labels present in the warp (an OR of the lanes' active labels), visited in ascending order.
      unsigned long long warp_labels[kLabelMaskWords];
#pragma unroll
      for (int word = 0; word < kLabelMaskWords; ++word) {
        unsigned long long bits = valid ? active_labels[word] : 0ull;
#pragma unroll
        for (int offset = 16; offset > 0; offset >>= 1) bits |= __shfl_xor_sync(0xffffffffu, bits, offset);
        warp_labels[word] = bits;
      }
#pragma unroll
      for (int word = 0; word < kLabelMaskWords; ++word)
        for (unsigned long long remaining = warp_labels[word]; remaining != 0ull; remaining &= remaining - 1ull) {
          const int label = word * 64 + __ffsll(static_cast<long long>(remaining)) - 1;
          const bool mine = valid && ((active_labels[word] >> (label % 64)) & 1ull) != 0ull;
          double w = 0.0;
          float w_float = 0.f;
          if (mine) {
            w_float = divRn(rawWeight(p, plane, idx, label, mass), active_mass);
            w = double(w_float);
          }
          double* sums = region + label * kLabelStride;
          // The 27 values of H and g: each warp total in float (32 float products; the CPU's double sums agree to
          // ~1e-7 relative, test_motion_estimation_cuda.cpp), then lane k adds value k to the double sums, all lanes at
          // once. Double shuffle trees and 27 additions by lane 0 in turn took about 60 % of this kernel (ncu, H100).
          // (A reduce-scatter over the lanes, 31 shuffles instead of 27 x 5, was tried: 5-15 % slower at every level.)
          const float ww = float(w * w), wf = float(w);
          float lane_total = 0.f;
#pragma unroll
          for (int k = 0; k < kUpper; ++k) {
            const float s = warpAllSum(in_view ? ww * Hm[k] : 0.f);
            if (lane == k) lane_total = s;
          }
#pragma unroll
          for (int k = 0; k < 6; ++k) {
            const float s = warpAllSum(in_view ? wf * gm[k] : 0.f);
            if (lane == kUpper + k) lane_total = s;
          }
          if (lane < kUpper + 6) sums[lane] += double(lane_total);
          const double label_cost = !mine     ? 0.0
                                    : in_view ? w * double(mass) * cost
                                              : double(mulRn(mass, w_float)) * p.out_of_view_cost;
          const double s_cost = warpSum(label_cost);
          const double s_pixels = warpSum(mine && in_view ? w * double(mass) : 0.0);
          if (lane == 0) {
            sums[kLabelCost] += s_cost;
            sums[kLabelPixels] += s_pixels;
          }
        }
    }
    __syncthreads();
  }
  double* partial = p.block_partials + (std::size_t(blockIdx.y) * gridDim.x + blockIdx.x) * block_values;
  for (int k = threadIdx.x; k < block_values; k += blockDim.x) {
    double sum = 0.0;
    for (int r = 0; r < regions; ++r) sum += block_sums[r * block_values + k];
    partial[k] = sum;
  }
}

// Adds the blocks' partial sums in block order: one warp per value, lane l takes blocks l, l + 32, ...; blockIdx.y is
// the batch (its partials and sums follow the previous batch's).
__global__ void reduceBlockPartials(const double* __restrict__ partials, int blocks, int values,
                                    double* __restrict__ sums, const int* skip) {
  if (skip && *skip) return;
  partials += std::size_t(blockIdx.y) * std::size_t(blocks) * std::size_t(values);
  sums += std::size_t(blockIdx.y) * std::size_t(values);
  const int value = int((std::size_t(blockIdx.x) * blockDim.x + threadIdx.x) >> 5);
  const int lane = threadIdx.x & 31;
  if (value >= values) return;  // whole warps leave together (value is warp-uniform)
  double s = 0.0;
  for (int b = lane; b < blocks; b += 32) s += partials[std::size_t(b) * values + value];
  s = warpSum(s);
  if (lane == 0) sums[value] = s;
}

// Off-diagonal block of the label pair (a, b), a < b: sum over the blended pixels of w_a w_b mass Hp
// (the CPU adds (w_a w_b) Hd to blocks (a, b) and (b, a)). Block (chunk, pair) sums the blended pixels of its chunk
// of the level into partials[(pair * chunks + chunk) * kUpper + k]; addChunksKernel adds the chunks in order. (One
// block per pair over a CUB-compacted list of the blended pixels was latency-bound: 42-65 us per call at 320x240,
// ncu; the compaction itself took two more launches.)

// The sums of one pair over one chunk (every thread of the block calls it: it has barriers).
__device__ __forceinline__ void accumulatePairInChunk(const KernelParams& p, int chunk_pixels, std::size_t plane, int a,
                                                      int b, double (*warp_sums)[kUpper], double* out) {
  double acc[kUpper];
#pragma unroll
  for (int k = 0; k < kUpper; ++k) acc[k] = 0.0;
  const std::size_t begin = std::size_t(blockIdx.x) * std::size_t(chunk_pixels);
  const std::size_t end = begin + std::size_t(chunk_pixels) < plane ? begin + std::size_t(chunk_pixels) : plane;
  bool any = false;  // this thread added a pixel in which both labels are active
  for (std::size_t idx = begin + threadIdx.x; idx < end; idx += blockDim.x) {
    if (!p.blended[idx]) continue;
    const float mass = p.mass[idx];
    const float wa_raw = rawWeight(p, plane, idx, a, mass), wb_raw = rawWeight(p, plane, idx, b, mass);
    if (!(wa_raw >= p.min_weight && wb_raw >= p.min_weight)) continue;
    any = true;
    const float active_mass = p.active_mass[idx];
    const double wab = double(divRn(wa_raw, active_mass)) * double(divRn(wb_raw, active_mass));
#pragma unroll
    for (int k = 0; k < kUpper; ++k) acc[k] += wab * double(p.blended_hessian[k * plane + idx]);
  }
  // Sums that nothing was added to are +0.0, as the shuffle tree over zeros would leave them. Both labels are in the
  // chunk's mask far more often than they share a pixel (a chunk across the boundaries a|c and b|c has a and b in its
  // mask): the block, or a warp, whose pixels never have both skips the reduction.
  if (__syncthreads_or(any) == 0) {
    if (threadIdx.x < kUpper) out[threadIdx.x] = 0.0;
    return;
  }
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  const bool warp_any = __any_sync(0xffffffffu, any);  // warp-uniform
#pragma unroll
  for (int k = 0; k < kUpper; ++k) {
    const double s = warp_any ? warpSum(acc[k]) : 0.0;
    if (lane == 0) warp_sums[warp][k] = s;
  }
  __syncthreads();
  if (threadIdx.x < kUpper) {
    double s = 0.0;
    for (int w = 0; w < kWarps; ++w) s += warp_sums[w][threadIdx.x];
    out[threadIdx.x] = s;
  }
  __syncthreads();  // warp_sums is read before the block's next pair overwrites it
}

// Block (chunk, y) takes the pairs y, y + gridDim.y, ...: one pair per block where chunks are few (coarse levels), a
// few where they are many, so that a fine level's chunks x pairs blocks, nearly all of which find the pair absent
// and exit, do not cost a launch wave each. The sums per (chunk, pair) are the same whatever the stride.
__global__ void __launch_bounds__(kThreads)
    accumulatePairs(const KernelParams p, int chunk_pixels, double* __restrict__ partials) {
  if (p.skip && *p.skip) return;
  __shared__ double warp_sums[kWarps][kUpper];
  const int n = p.motion_labels, pairs = n * (n - 1) / 2;
  const std::size_t plane = std::size_t(p.width) * p.height;
  const unsigned long long* mask = p.chunk_labels + std::size_t(blockIdx.x) * kLabelMaskWords;
  for (int pair = int(blockIdx.y); pair < pairs; pair += int(gridDim.y)) {
    int a = 0, rest = pair;
    while (rest >= n - 1 - a) {  // pair index -> (a, b), row-major over the upper triangle
      rest -= n - 1 - a;
      ++a;
    }
    const int b = a + 1 + rest;
    double* out = partials + (std::size_t(pair) * gridDim.x + blockIdx.x) * kUpper;
    if (!((mask[a / 64] >> (a % 64)) & 1ull) || !((mask[b / 64] >> (b % 64)) & 1ull)) {  // the pair never meets here
      if (threadIdx.x < kUpper) out[threadIdx.x] = 0.0;
      continue;
    }
    accumulatePairInChunk(p, chunk_pixels, plane, a, b, warp_sums, out);
  }
}

// ----------------------------------------------------------------- the IRLS loop on the device
// One iteration's step control and solve after the sums (estimateMotionsWith's host loop, the same
// motion_step_control.h), in one block, so that a level's iterations are queued at once and the host reads the
// result once per level instead of once per iteration.

constexpr int kStepThreads = 512;  // 16 warps for the rank-6 updates of a group's factorization
static_assert(2 * kMaxMotionLabels <= kStepThreads, "irlsStep: a thread per label, two per label for the twist update");

/// @brief The state of a level's device loop (read by the host once, at the end of the level).
struct IrlsState {
  int done;        ///< the loop has stopped: the kernels still queued return at once
  int stop;        ///< MotionStop
  int iterations;  ///< accumulations done
  int pixels_used;
  int largest_group;  ///< most labels coupled in one solve
  double cost_before, cost_after;
};

struct StepParams {
  const double* sums = nullptr;  // per label kLabelStride values, then cost and pixels, then the pairs' kUpper each
  int n = 0, iteration = 0;
  bool last = false;  // the last iteration only checks the previous step
  double min_label_pixels = 0, min_damping = 0, min_update = 0, min_coupling = 0;
  MotionLabelControl* control = nullptr;
  double* twists = nullptr;        // 6 per label: the current linearisation point
  LabelMotion* motions = nullptr;  // written for the next accumulation
  IrlsState* state = nullptr;
  double* matrix =
      nullptr;  // a group of coupled labels: (6n + 1)^2 with its right-hand side (global when shared is too small)
  bool matrix_in_shared = false;  // dynamic shared memory: the matrix (when it fits), then the 6 x 6n panel
};

// Row and column of the k-th value of a symmetric 6x6 block's upper triangle (row-major, r <= c).
__constant__ int kUpperRow[kUpper] = {0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 4, 4, 5};
__constant__ int kUpperCol[kUpper] = {0, 1, 2, 3, 4, 5, 1, 2, 3, 4, 5, 2, 3, 4, 5, 3, 4, 5, 4, 5, 5};

__device__ __forceinline__ int pairIndex(int n, int a, int b) { return a * n - a * (a + 1) / 2 + (b - a - 1); }

// Index of diagonal entry r of a 6x6 block's upper triangle (row-major).
__constant__ int kUpperDiagonal[6] = {0, 6, 11, 15, 18, 20};

// The damped diagonal of label i's block (upper triangle in `upper`), as the host loop damps it.
__device__ __forceinline__ void dampedLabelDiagonal(const double* upper, double damping, double diagonal[6]) {
  double block_max = upper[0];
  for (int r = 1; r < 6; ++r) block_max = upper[kUpperDiagonal[r]] > block_max ? upper[kUpperDiagonal[r]] : block_max;
  for (int r = 0; r < 6; ++r) diagonal[r] = dampedDiagonal(upper[kUpperDiagonal[r]], damping, block_max);
}

// Damped 6x6 block of label i (upper triangle in `upper`), written into M at (r0, c0) with leading dimension ld.
__device__ __forceinline__ void dampedLabelBlock(const double* upper, double damping, double* M, int ld, int r0) {
  double diagonal[6];
  dampedLabelDiagonal(upper, damping, diagonal);
  int k = 0;
  for (int r = 0; r < 6; ++r)
    for (int c = r; c < 6; ++c, ++k) {
      const double v = r == c ? diagonal[r] : upper[k];
      M[(r0 + r) * ld + r0 + c] = v;
      M[(r0 + c) * ld + r0 + r] = v;
    }
}

// The 6x6 factors, solves and coupling strengths of motion_step_control.h in their reciprocal-pivot form (PivotForm):
// the one thread that handles a label multiplies where the host's loop divides.

__global__ void __launch_bounds__(kStepThreads) irlsStep(const StepParams q) {
  extern __shared__ double shared_matrix[];
  __shared__ int s_stop;
  __shared__ bool frozen[kMaxMotionLabels];
  __shared__ int root[kMaxMotionLabels], members[kMaxMotionLabels], group_start[kMaxMotionLabels + 1];
  __shared__ int group_count;
  __shared__ int s_largest;
  __shared__ double delta[6 * kMaxMotionLabels];
  __shared__ double rhs[6 * kMaxMotionLabels];
  __shared__ double inverse_diagonal[6 * kMaxMotionLabels];  // of the group's Cholesky factor
  __shared__ double label_factor[21 * kMaxMotionLabels];     // each damped block's factor (reciprocal pivots): the
                                                             // coupling test, then the label's own solve
  __shared__ unsigned coupled[(kMaxMotionLabels * (kMaxMotionLabels - 1) / 2 + 31) / 32];
  __shared__ double largest_step[kStepThreads / 32];
  const int n = q.n, tid = threadIdx.x;
  const double* pair_sums = q.sums + n * kLabelStride + 2;
  const int pairs = n * (n - 1) / 2;
  IrlsState& state = *q.state;

  if (tid == 0) {
    s_stop = state.done;
    if (!s_stop) {
      const double cost = q.sums[n * kLabelStride];
      const int pixels = int(llround(q.sums[n * kLabelStride + 1]));
      if (q.iteration == 0) state.cost_before = cost;
      state.cost_after = cost;
      state.pixels_used = pixels;
      state.iterations = q.iteration + 1;
      if (pixels < 6) {
        state.stop = int(MotionStop::TooFewPixels);
        state.done = 1;
        s_stop = 1;
      }
    }
  }
  for (int w = tid; w < (pairs + 31) / 32; w += blockDim.x) coupled[w] = 0u;
  __syncthreads();
  if (s_stop) return;

  // Accept or undo each label's last step.
  for (int i = tid; i < n; i += blockDim.x) {
    const double* label = q.sums + i * kLabelStride;
    frozen[i] = controlMotionLabel(label[kLabelCost], label[kLabelPixels], q.min_label_pixels, q.min_damping,
                                   q.twists + 6 * i, q.control[i]);
    if (q.min_coupling > 0.0 && !frozen[i]) {
      double A[36];
      dampedLabelBlock(label, q.control[i].damping, A, 6, 0);
      choleskyLower6<PivotForm::Reciprocal>(A, label_factor + 21 * i);
    }
  }
  __syncthreads();
  if (q.last) {  // the last iteration only checks the previous step
    if (tid == 0) state.done = 1;
    return;
  }

  // Groups of coupled labels (a frozen label's rows and columns are zero: it is coupled to none; a coupling weaker
  // than min_coupling does not join two labels' groups, motionLabelsCoupled).
  int any_coupled = 0;
  for (int pair = tid; pair < pairs; pair += blockDim.x) {
    int a = 0, rest = pair;
    while (rest >= n - 1 - a) {
      rest -= n - 1 - a;
      ++a;
    }
    const int b = a + 1 + rest;
    if (frozen[a] || frozen[b]) continue;
    const double* block = pair_sums + std::size_t(pair) * kUpper;
    int nonzero = 0;  // every value read (no short cut): 21 loads in flight at once
#pragma unroll
    for (int k = 0; k < kUpper; ++k) nonzero |= block[k] != 0.0 ? 1 : 0;
    double strength = 0.0;
    if (nonzero && q.min_coupling > 0.0) {
      double C[36];
      for (int k = 0; k < kUpper; ++k)
        C[kUpperRow[k] * 6 + kUpperCol[k]] = C[kUpperCol[k] * 6 + kUpperRow[k]] = block[k];
      strength = motionCouplingStrength<PivotForm::Reciprocal>(label_factor + 21 * a, C, label_factor + 21 * b);
    }
    if (motionLabelsCoupled(strength, nonzero != 0, q.min_coupling)) {
      atomicOr(&coupled[pair / 32], 1u << (pair % 32));
      any_coupled = 1;
    }
  }
  if (!__syncthreads_or(any_coupled)) {  // also the barrier after the atomicOr's
    // No coupling kept (the common case with motion_min_coupling > 0): every label is its own group, set in parallel
    // instead of by the propagation below.
    for (int i = tid; i < n; i += blockDim.x) {
      root[i] = i;
      members[i] = i;
      group_start[i] = i;
    }
    if (tid == 0) {
      group_start[n] = n;
      group_count = n;
      state.largest_group = max(state.largest_group, 1);
    }
  } else {
    // Connected components of the coupling graph, one label per thread: every label takes the smallest root among
    // itself and the labels coupled to it until nothing changes, so each group's root is its smallest label, as a
    // serial union-find that roots every group at its smallest label gives.
    if (tid < n) root[tid] = tid;
    if (tid == 0) s_largest = 0;
    __syncthreads();
    for (;;) {
      int best = tid < n ? root[tid] : 0;
      if (tid < n)
        for (int j = 0; j < n; ++j) {
          if (j == tid) continue;
          const int pair = j < tid ? pairIndex(n, j, tid) : pairIndex(n, tid, j);
          if ((coupled[pair / 32] >> (pair % 32)) & 1u) best = min(best, root[j]);
        }
      __syncthreads();  // every root read before any changes
      const int changed = tid < n && best < root[tid];
      if (changed) root[tid] = best;
      if (!__syncthreads_or(changed)) break;
    }
    // Groups in ascending order of their roots, members ascending within a group (the order of the serial union-find
    // this replaced, which the host loop's grouping also gives).
    const int roots = __syncthreads_count(tid < n && root[tid] == tid);
    if (tid < n) {
      const int r = root[tid];
      int start = 0, rank = 0, position = 0, size = 0;
      for (int j = 0; j < n; ++j) {
        const int rj = root[j];
        start += rj < r ? 1 : 0;
        rank += rj == j && j < r ? 1 : 0;
        position += rj == r && j < tid ? 1 : 0;
        size += rj == r ? 1 : 0;
      }
      members[start + position] = tid;
      if (tid == r) {
        group_start[rank] = start;
        atomicMax(&s_largest, size);
      }
    }
    __syncthreads();
    if (tid == 0) {
      group_start[roots] = n;
      group_count = roots;
      state.largest_group = max(state.largest_group, s_largest);
    }
  }
  __syncthreads();

  // Single labels: a 6x6 solve per thread.
  for (int g = tid; g < group_count; g += blockDim.x) {
    if (group_start[g + 1] - group_start[g] != 1) continue;
    const int i = members[group_start[g]];
    const double* label = q.sums + i * kLabelStride;
    double x[6] = {0, 0, 0, 0, 0, 0};
    if (!frozen[i]) {
      // The coupling test factored this block already (same damping); otherwise factor it here.
      double F[21], b[6];
      const double* factor = label_factor + 21 * i;
      if (!(q.min_coupling > 0.0)) {
        double M[36];
        dampedLabelBlock(label, q.control[i].damping, M, 6, 0);
        choleskyLower6<PivotForm::Reciprocal>(M, F);
        factor = F;
      }
      for (int k = 0; k < 6; ++k) b[k] = -label[kUpper + k];
      choleskySolve6<PivotForm::Reciprocal>(factor, b, x);
    }
    for (int k = 0; k < 6; ++k) delta[6 * i + k] = x[k];
  }

  // Groups of several labels: the whole block factors the group's dense matrix (Cholesky by label blocks) with the
  // right-hand side appended as row N, so the factorization leaves the forward substitution's result in that row.
  double* M = q.matrix_in_shared ? shared_matrix : q.matrix;
  // 6 x (6n + 1), column-major, after the matrix when it is in shared memory
  double* panel = q.matrix_in_shared ? shared_matrix + std::size_t(6 * n + 1) * (6 * n + 1) : shared_matrix;
  for (int g = 0; g < group_count; ++g) {
    const int m = group_start[g + 1] - group_start[g];
    if (m == 1) continue;
    const int* group = members + group_start[g];
    const int N = 6 * m, ld = N + 1, rows = N + 1;  // ld odd: column reads hit distinct banks
    // Off-diagonal label blocks from the pair sums (each value read once, written to its four places), then the
    // damped diagonal blocks and the right-hand side.
    const int pair_values = m * m * kUpper;
#pragma unroll 4
    for (int e = tid; e < pair_values; e += blockDim.x) {
      const int ga = e / (m * kUpper), rest = e - ga * m * kUpper, gb = rest / kUpper, k = rest - gb * kUpper;
      if (ga >= gb) continue;
      const double v = pair_sums[std::size_t(pairIndex(n, group[ga], group[gb])) * kUpper + k];
      const int r = kUpperRow[k], c = kUpperCol[k];
      M[(6 * ga + r) * ld + 6 * gb + c] = v;
      M[(6 * ga + c) * ld + 6 * gb + r] = v;
      M[(6 * gb + r) * ld + 6 * ga + c] = v;
      M[(6 * gb + c) * ld + 6 * ga + r] = v;
    }
    for (int k = tid; k < m; k += blockDim.x) {
      const int i = group[k];
      const double* label = q.sums + i * kLabelStride;
      dampedLabelBlock(label, q.control[i].damping, M, ld, 6 * k);
      for (int c = 0; c < 6; ++c) {
        M[N * ld + 6 * k + c] = -label[kUpper + c];
        // Pivot floor (held here until the factorization replaces it by the pivot's reciprocal): rounding can leave
        // a matrix without damping (motion_damping 0) barely indefinite; the host's pivoted LDLT still gives a step,
        // an unpivoted Cholesky would give NaN.
        inverse_diagonal[6 * k + c] = 1e-12 * M[(6 * k + c) * ld + 6 * k + c];
      }
    }
    __syncthreads();
    // Per block of 6 columns: every thread factors the 6x6 diagonal block in registers (the same values in all: no
    // barrier between it and the panel), the threads of the panel rows below it (the right-hand side's row
    // included) compute them, kept column-major in `panel` as well, then the rank-6 update of the trailing lower
    // triangle (rows over warps, columns over lanes: contiguous, conflict-free shared-memory reads). Two barriers.
    const int warp = tid >> 5, lane = tid & 31, warps = blockDim.x >> 5;
    for (int c0 = 0; c0 < N; c0 += 6) {
      double L[6][6], inverse[6], floor[6];
#pragma unroll
      for (int r = 0; r < 6; ++r) {
        floor[r] = inverse_diagonal[c0 + r];
#pragma unroll
        for (int c = 0; c <= r; ++c) L[r][c] = M[(c0 + r) * ld + c0 + c];
      }
#pragma unroll
      for (int c = 0; c < 6; ++c) {
        double d = L[c][c];
#pragma unroll
        for (int t = 0; t < c; ++t) d -= L[c][t] * L[c][t];
        d = d > floor[c] ? d : floor[c];
        inverse[c] = rsqrt(d);  // one operation on the serial chain instead of a square root and a division
        L[c][c] = d * inverse[c];
#pragma unroll
        for (int r = c + 1; r < 6; ++r) {
          double v = L[r][c];
#pragma unroll
          for (int t = 0; t < c; ++t) v -= L[r][t] * L[c][t];
          L[r][c] = v * inverse[c];
        }
      }
      for (int i = c0 + 6 + tid; i < rows; i += blockDim.x) {
        double l[6];
#pragma unroll
        for (int c = 0; c < 6; ++c) {
          double v = M[i * ld + c0 + c];
#pragma unroll
          for (int t = 0; t < c; ++t) v -= l[t] * L[c][t];
          l[c] = v * inverse[c];
          M[i * ld + c0 + c] = l[c];
          panel[c * rows + i] = l[c];
        }
      }
      __syncthreads();
      if (tid == 0) {  // after the barrier: every thread has read the block before it is overwritten
#pragma unroll
        for (int r = 0; r < 6; ++r) {
          inverse_diagonal[c0 + r] = inverse[r];
#pragma unroll
          for (int c = 0; c <= r; ++c) M[(c0 + r) * ld + c0 + c] = L[r][c];
        }
      }
      for (int i = c0 + 6 + warp; i < rows; i += warps) {
        double l[6];
        for (int t = 0; t < 6; ++t) l[t] = panel[t * rows + i];
        // A row whose panel is zero (its label not coupled to this block's, and no fill-in yet) changes nothing.
        if (l[0] == 0.0 && l[1] == 0.0 && l[2] == 0.0 && l[3] == 0.0 && l[4] == 0.0 && l[5] == 0.0) continue;
        const int last = i < N ? i : N - 1;  // the right-hand side's row has no diagonal entry
        for (int k = c0 + 6 + lane; k <= last; k += 32) {
          double v = M[i * ld + k];
          for (int t = 0; t < 6; ++t) v -= l[t] * panel[t * rows + k];
          M[i * ld + k] = v;
        }
      }
      __syncthreads();
    }
    if (tid < 32) {  // back substitution L^T x = y by one warp (y: the factored right-hand side's row)
      for (int k = tid; k < N; k += 32) rhs[k] = M[N * ld + k];
      __syncwarp();
      for (int j = N - 1; j >= 0; --j) {
        const double x = rhs[j] * inverse_diagonal[j];
        __syncwarp();
        for (int i = tid; i < j; i += 32) rhs[i] -= M[j * ld + i] * x;
        if (tid == 0) rhs[j] = x;
        __syncwarp();
      }
    }
    __syncthreads();
    for (int k = tid; k < N; k += blockDim.x) delta[6 * group[k / 6] + k % 6] = rhs[k];
    __syncthreads();
  }
  __syncthreads();

  // A non-finite step stops the loop (the host's SolveFailed); otherwise the trust region and the update.
  double largest = 0.0;
  bool finite = true;
  for (int i = tid; i < n; i += blockDim.x) {
    double d[6];
    for (int k = 0; k < 6; ++k) {
      d[k] = delta[6 * i + k];
      finite = finite && isfinite(d[k]);
    }
    if (!finite) continue;
    largest = fmax(largest, limitMotionStep(d));
    for (int k = 0; k < 6; ++k) delta[6 * i + k] = d[k];
  }
  finite = __syncthreads_and(finite);
  if (!finite) {
    if (tid == 0) {
      state.stop = int(MotionStop::SolveFailed);
      state.done = 1;
    }
    return;
  }
  for (int offset = 16; offset > 0; offset >>= 1)
    largest = fmax(largest, __shfl_xor_sync(0xffffffffu, largest, offset));
  if ((tid & 31) == 0) largest_step[tid >> 5] = largest;
  __syncthreads();
  // Twists move by the (scaled) step and the next accumulation's linearisation points follow.
  // Two threads per label: the transform on one, the left Jacobian on the other (each a long serial chain in double).
  {
    const int i = tid >> 1;
    double xi[6];
    if (tid < 2 * n)
      for (int k = 0; k < 6; ++k) xi[k] = q.twists[6 * i + k] + delta[6 * i + k];
    __syncthreads();  // both threads of a label have read its twist before it is overwritten
    if (tid < 2 * n) {
      LabelMotion& motion = q.motions[i];
      if (tid & 1) {
        se3LeftJacobianDevice(xi, motion.left_jacobian);
      } else {
        se3ExpDevice(xi, motion.transform);
        for (int k = 0; k < 6; ++k) {
          q.twists[6 * i + k] = xi[k];
          motion.twist[k] = xi[k];
        }
      }
    }
  }
  if (tid == 0) {
    double all = 0.0;
    for (int w = 0; w < kStepThreads / 32; ++w) all = fmax(all, largest_step[w]);
    if (all < q.min_update) {
      state.stop = int(MotionStop::SmallUpdate);
      state.done = 1;
    }
  }
}

// ----------------------------------------------------------------- refitUnions on the device
// One motion per group of labels, refitted on their union's pixels (label_adaptation.cpp's refitUnions, the host loop,
// step for step: the same passes and the step control of union_refit_step.h; the 6x6 solves by Cholesky in double
// here, Eigen's LDLT there). One warp per group; the state stays on the device between the passes.

/// @brief A group's fit between the passes (read by the host once, after the last pass).
struct UnionRefitState {
  double twist[6];           ///< the last accepted twist
  double proposed[6];        ///< the twist of the pass in flight
  double curvature[kUpper];  // H at `twist`, upper triangle (row-major, r <= c)
  double gradient[6];
  double cost, pixels, damping;
  int iterations;       ///< accepted steps
  int proposed_finite;  ///< 0: the step was not finite; the pass ran at `twist` and is rejected after it
};

struct UnionRefitParams {
  const double* sums = nullptr;         // the pass's per-label sums (kLabelStride values per label), batch after batch
  std::size_t batch_values = 0;         // values per batch in `sums`
  const int* batch_of_group = nullptr;  // per group: the batch of the pass it shares
  const int* group_of_label = nullptr;  // per batch and motion label (batch * n + label): its group, or -1
  int n = 0, groups = 0;
  bool first = false;    // the pass at the starts: take its sums, no acceptance test
  bool propose = false;  // a further pass follows: propose its step and write the members' motions
  double min_damping = 0;
  UnionRefitState* state = nullptr;
  double* member_cost = nullptr;   // per batch and motion label: its cost at its group's accepted twist
  LabelMotion* motions = nullptr;  // per batch and motion label
};

// x = A^-1 b for a symmetric positive definite 6x6 A (row-major); false when the factorisation fails.
__device__ bool solveSpd6(double A[36], const double b[6], double x[6]) {
  for (int j = 0; j < 6; ++j) {
    double d = A[j * 6 + j];
    for (int k = 0; k < j; ++k) d -= A[j * 6 + k] * A[j * 6 + k];
    if (!(d > 0.0)) return false;
    const double l = sqrt(d);
    A[j * 6 + j] = l;
    for (int i = j + 1; i < 6; ++i) {
      double v = A[i * 6 + j];
      for (int k = 0; k < j; ++k) v -= A[i * 6 + k] * A[j * 6 + k];
      A[i * 6 + j] = v / l;
    }
  }
  double y[6];
  for (int i = 0; i < 6; ++i) {
    double v = b[i];
    for (int k = 0; k < i; ++k) v -= A[i * 6 + k] * y[k];
    y[i] = v / A[i * 6 + i];
  }
  for (int i = 5; i >= 0; --i) {
    double v = y[i];
    for (int k = i + 1; k < 6; ++k) v -= A[k * 6 + i] * x[k];
    x[i] = v / A[i * 6 + i];
  }
  return true;
}

// One warp per group (kRefitWarps a block). The lanes find the group's members and sum their sums, lane k value k (in
// ascending label order, as one thread summed them: the same doubles); lane 0 then takes the step, lanes 0 and 1
// compute the next linearisation point's exponential and left Jacobian side by side, and the lanes write it to the
// members. (One thread per group took 13.8 us a call on an H100, this 10.8: ncu, docs/decisions/0017.)
constexpr int kRefitWarps = 2;

__global__ void __launch_bounds__(kRefitWarps * 32) unionRefitStep(const UnionRefitParams q) {
  __shared__ double values[kRefitWarps][kLabelStride];
  __shared__ double proposed[kRefitWarps][6];
  __shared__ int take_shared[kRefitWarps];
  __shared__ float transform[kRefitWarps][12];
  __shared__ float left_jacobian[kRefitWarps][36];
  const int warp = int(threadIdx.x) / 32, lane = int(threadIdx.x) & 31;
  const int g = int(blockIdx.x) * kRefitWarps + warp;
  if (g >= q.groups) return;  // warp-uniform
  UnionRefitState& st = q.state[g];
  // This group's batch: its sums, its labels' groups, costs and motions.
  const std::size_t batch = std::size_t(q.batch_of_group[g]);
  const double* sums = q.sums + batch * q.batch_values;
  const int* group_of_label = q.group_of_label + batch * std::size_t(q.n);
  double* member_cost = q.member_cost + batch * std::size_t(q.n);
  LabelMotion* motions = q.motions + batch * std::size_t(q.n);
  // The union's model at the pass's twist: its members' sums, in ascending label order.
  double total = 0.0;
  for (int base = 0; base < q.n; base += 32) {
    const int i = base + lane;
    unsigned members = __ballot_sync(0xffffffffu, i < q.n && group_of_label[i] == g);
    for (; members != 0u; members &= members - 1u) {
      const int label = base + __ffs(int(members)) - 1;
      if (lane < kLabelStride) total += sums[std::size_t(label) * kLabelStride + lane];
    }
  }
  if (lane < kLabelStride) values[warp][lane] = total;
  __syncwarp();
  if (lane == 0) {
    const double* H = values[warp];
    const double* grad = H + kUpper;
    const double cost = H[kLabelCost], pixels = H[kLabelPixels];
    bool take = q.first;
    if (!q.first) {
      take = st.proposed_finite && cost <= st.cost;
      st.damping = take ? union_refit::dampingAfterAccept(st.damping, q.min_damping)
                        : union_refit::dampingAfterReject(st.damping);
      if (take) {
        for (int k = 0; k < 6; ++k) st.twist[k] = st.proposed[k];
        ++st.iterations;
      }
    }
    if (take) {
      for (int k = 0; k < kUpper; ++k) st.curvature[k] = H[k];
      for (int k = 0; k < 6; ++k) st.gradient[k] = grad[k];
      st.cost = cost;
      st.pixels = pixels;
    }
    take_shared[warp] = take ? 1 : 0;
    if (q.propose) {
      // The next step from the accepted model: (H + (damping + ridge) s I) d = -g, s the largest diagonal entry.
      double A[36];
      double scale = 1e-12;
      {
        int k = 0;
        for (int r = 0; r < 6; ++r)
          for (int c = r; c < 6; ++c, ++k) {
            A[r * 6 + c] = st.curvature[k];
            A[c * 6 + r] = st.curvature[k];
          }
        for (int r = 0; r < 6; ++r) scale = fmax(scale, A[r * 6 + r]);
      }
      for (int r = 0; r < 6; ++r) A[r * 6 + r] += (st.damping + union_refit::kRidge) * scale;
      double minus_g[6], d[6];
      for (int k = 0; k < 6; ++k) minus_g[k] = -st.gradient[k];
      bool finite = solveSpd6(A, minus_g, d);
      if (finite) {
        const double t = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        const double r = sqrt(d[3] * d[3] + d[4] * d[4] + d[5] * d[5]);
        const double limit = fmax(1.0, fmax(t / union_refit::kMaxTranslation, r / union_refit::kMaxRotation));
        for (int k = 0; k < 6; ++k) {
          d[k] /= limit;
          finite = finite && isfinite(d[k]);
        }
      }
      st.proposed_finite = finite ? 1 : 0;
      for (int k = 0; k < 6; ++k) proposed[warp][k] = st.proposed[k] = finite ? st.twist[k] + d[k] : st.twist[k];
    }
  }
  __syncwarp();
  // The members' costs at an accepted twist, and their linearisation points for the next pass.
  const bool take = take_shared[warp] != 0;
  if (q.propose) {
    if (lane == 0) se3ExpDevice(proposed[warp], transform[warp]);
    if (lane == 1) se3LeftJacobianDevice(proposed[warp], left_jacobian[warp]);
  }
  __syncwarp();
  for (int base = 0; base < q.n; base += 32) {
    const int i = base + lane;
    unsigned members = __ballot_sync(0xffffffffu, i < q.n && group_of_label[i] == g);
    for (; members != 0u; members &= members - 1u) {
      const int label = base + __ffs(int(members)) - 1;
      if (take && lane == 0) member_cost[label] = sums[std::size_t(label) * kLabelStride + kLabelCost];
      if (!q.propose) continue;
      LabelMotion& m = motions[label];
      if (lane < 12) m.transform[lane] = transform[warp][lane];
      for (int k = lane; k < 36; k += 32) m.left_jacobian[k] = left_jacobian[warp][k];
      if (lane < 6) m.twist[lane] = proposed[warp][lane];
    }
  }
}

/// @brief A pair's start choice on the device (refitPairs): its labels, their costs under their own twists and the
/// twists.
struct UnionStartChoice {
  int a = 0, b = 0;
  double own_a = 0, own_b = 0;
  double twist_a[6] = {}, twist_b[6] = {};
};

// After the swapped pass (each batch's pairs with their motions exchanged): each pair starts from a's motion where
// own_a + (b's cost under a's motion) <= (a's cost under b's motion) + own_b, else from b's (label_adaptation.cpp's
// refitPairsFromTheBetterMotion, the same doubles in the same order). The swapped table holds a's motion at b and b's
// at a: the chosen one becomes both members' motion for the refit's first pass.
__global__ void chooseUnionStarts(const double* __restrict__ sums, std::size_t batch_values,
                                  const int* __restrict__ batch_of_group, int n, int groups,
                                  const UnionStartChoice* __restrict__ choices, const LabelMotion* __restrict__ swapped,
                                  UnionRefitState* __restrict__ state, LabelMotion* __restrict__ motions) {
  const int g = int(blockIdx.x * blockDim.x + threadIdx.x);
  if (g >= groups) return;
  const UnionStartChoice c = choices[g];
  const std::size_t batch = std::size_t(batch_of_group[g]);
  const double* batch_sums = sums + batch * batch_values;
  const double a_under_b = batch_sums[std::size_t(c.a) * kLabelStride + kLabelCost];
  const double b_under_a = batch_sums[std::size_t(c.b) * kLabelStride + kLabelCost];
  const bool from_a = c.own_a + b_under_a <= a_under_b + c.own_b;
  UnionRefitState& st = state[g];
  for (int k = 0; k < 6; ++k) st.twist[k] = st.proposed[k] = from_a ? c.twist_a[k] : c.twist_b[k];
  const LabelMotion start = swapped[batch * std::size_t(n) + std::size_t(from_a ? c.b : c.a)];
  motions[batch * std::size_t(n) + std::size_t(c.a)] = start;
  motions[batch * std::size_t(n) + std::size_t(c.b)] = start;
}

// ----------------------------------------------------------------- host side

void requireImage(const char* name, const ImageF& image, int width, int height, int channels) {
  if (image.width != width || image.height != height || image.channels != channels ||
      image.data.size() != std::size_t(width) * height * channels)
    throw InputError(std::string("CUDA motion step: ") + name + " is " +
                     imageSizeText(image.width, image.height, image.channels) + " with " +
                     std::to_string(image.data.size()) + " values, expected " + imageSizeText(width, height, channels));
}

class CudaMotionAccumulator final : public cuda_detail::DeviceMotionAccumulator {
 public:
  /// `stream` null: the accumulator's own stream.
  explicit CudaMotionAccumulator(cudaStream_t stream) {
    int device = 0, optin = 0;
    MCFLOW_CUDA_CHECK(cudaGetDevice(&device));
    MCFLOW_CUDA_CHECK(cudaDeviceGetAttribute(&optin, cudaDevAttrMaxSharedMemoryPerBlockOptin, device));
    max_shared_bytes_ = std::size_t(std::max(optin, 48 * 1024));
    cudaFuncAttributes step_attributes{};
    MCFLOW_CUDA_CHECK(cudaFuncGetAttributes(&step_attributes, irlsStep));
    step_static_shared_ = step_attributes.sharedSizeBytes;
    // Both kernels may use all of the device's shared memory per block, set once: the attribute belongs to the kernel
    // (one per device, shared by every accumulator), so raising it only as far as one instance needs could be undone
    // by another, and without opting in, static plus dynamic shared memory must stay within 48 KiB.
    MCFLOW_CUDA_CHECK(cudaFuncSetAttribute(accumulateNormalEquations, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                           int(max_shared_bytes_)));
    MCFLOW_CUDA_CHECK(cudaFuncSetAttribute(irlsStep, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                           int(max_shared_bytes_ - step_static_shared_)));
    if (stream) {
      stream_ = stream;
    } else {
      own_stream_ = std::make_unique<cuda_detail::StreamHolder>();
      stream_ = own_stream_->stream;
    }
  }

  std::string name() const override { return "cuda"; }

  void setLevel(const PyramidLevel& frame1, const PyramidLevel& frame2, const SoftLabels& labels,
                const ImageU8* occluded, const Config& config) override {
    const int W = frame1.points.width, H = frame1.points.height;
    if (W <= 0 || H <= 0) throw InputError("CUDA motion step: empty level " + imageSizeText(W, H, 3));
    requireImage("frame-1 points", frame1.points, W, H, 3);
    requireImage("frame-1 intensity", frame1.intensity, W, H, 1);
    requireImage("frame-2 intensity", frame2.intensity, W, H, 1);
    requireImage("frame-2 depth", frame2.depth, W, H, 1);
    requireImage("frame-2 intensity gradient", frame2.intensity_grad, W, H, 2);
    requireImage("frame-2 depth gradient", frame2.depth_grad, W, H, 2);
    const std::size_t plane = std::size_t(W) * H;
    if (labels.width != W || labels.height != H || labels.count < 1 ||
        labels.data.size() != plane * std::size_t(labels.count))
      throw InputError("CUDA motion step: labels are " + imageSizeText(labels.width, labels.height, labels.count) +
                       " with " + std::to_string(labels.data.size()) + " values, the level is " + std::to_string(W) +
                       "x" + std::to_string(H));
    if (occluded && (occluded->width != W || occluded->height != H || occluded->data.size() != plane))
      throw InputError("CUDA motion step: occlusion mask is " + imageSizeText(occluded->width, occluded->height, 1) +
                       ", the level is " + std::to_string(W) + "x" + std::to_string(H));

    points1_.reserve(plane * 3);
    intensity1_.reserve(plane);
    intensity2_.reserve(plane);
    depth2_.reserve(plane);
    intensity_grad2_.reserve(plane * 2);
    depth_grad2_.reserve(plane * 2);
    labels_.reserve(std::max<std::size_t>(plane * std::size_t(labels.count), 1));
    occluded_.reserve(plane);
    upload(points1_.get(), frame1.points.ptr(), plane * 3);
    upload(intensity1_.get(), frame1.intensity.ptr(), plane);
    upload(intensity2_.get(), frame2.intensity.ptr(), plane);
    upload(depth2_.get(), frame2.depth.ptr(), plane);
    upload(intensity_grad2_.get(), frame2.intensity_grad.ptr(), plane * 2);
    upload(depth_grad2_.get(), frame2.depth_grad.ptr(), plane * 2);
    upload(labels_.get(), labels.data.data(), plane * std::size_t(labels.count));
    if (occluded) upload(occluded_.get(), occluded->ptr(), plane);
    // The caller's images may change after this call returns: wait until the copies are done.
    MCFLOW_CUDA_WAIT(stream_);
    cuda_detail::DeviceLevel level;
    level.width = W;
    level.height = H;
    level.intrinsics = frame2.intrinsics;
    level.points1 = {points1_.get(), W, H, 3};
    level.intensity1 = {intensity1_.get(), W, H, 1};
    level.intensity2 = {intensity2_.get(), W, H, 1};
    level.depth2 = {depth2_.get(), W, H, 1};
    level.intensity_grad2 = {intensity_grad2_.get(), W, H, 2};
    level.depth_grad2 = {depth_grad2_.get(), W, H, 2};
    bind(level, labels_.get(), labels.count, occluded ? occluded_.get() : nullptr, config);
  }

  void bind(const cuda_detail::DeviceLevel& level, const float* labels, int count, const std::uint8_t* occluded,
            const Config& config) override {
    if (level.width <= 0 || level.height <= 0 || count < 1)
      throw InputError("CUDA motion step: binding an empty level " + imageSizeText(level.width, level.height, count));
    if (count - 1 > kMaxMotionLabels)
      throw InputError("CUDA motion step: " + std::to_string(count - 1) + " motion labels, at most " +
                       std::to_string(kMaxMotionLabels));
    const std::size_t plane = std::size_t(level.width) * level.height;
    level_ = level;
    bound_labels_ = labels;
    bound_occluded_ = occluded;
    motion_labels_ = count - 1;
    config_ = config;
    blended_.reserve(plane);
    blended_hessian_.reserve(plane * kUpper);
    active_mass_.reserve(plane);
    mass_.reserve(plane);
  }

  void accumulate(const std::vector<Vector6d>& twists, MotionNormalEquations& out) override {
    accumulateSums(twists, out, true);
  }

  void accumulateLabelBlocks(const std::vector<Vector6d>& twists, MotionNormalEquations& out) override {
    accumulateSums(twists, out, false);
  }

  void accumulateLabelBlockSets(const std::vector<std::vector<Vector6d>>& twist_sets,
                                std::vector<MotionNormalEquations>& out) override {
    if (level_.width <= 0) throw InputError("CUDA motion step: a pass requested before setLevel() or bind()");
    const int n = motion_labels_, batches = int(twist_sets.size());
    for (const std::vector<Vector6d>& twists : twist_sets)
      if (int(twists.size()) != n)
        throw InputError("CUDA motion step: " + std::to_string(twists.size()) + " twists for " + std::to_string(n) +
                         " motion labels");
    out.assign(twist_sets.size(), MotionNormalEquations());
    for (MotionNormalEquations& equations : out) equations.reset(n);
    if (n == 0 || batches == 0) return;
    const int per_pass = batchesPerPass();
    if (batches > per_pass) {  // in several passes, each within the memory for the block partials
      for (int first = 0; first < batches; first += per_pass) {
        const int last = std::min(batches, first + per_pass);
        std::vector<MotionNormalEquations> part;
        accumulateLabelBlockSets({twist_sets.begin() + first, twist_sets.begin() + last}, part);
        std::move(part.begin(), part.end(), out.begin() + first);
      }
      return;
    }
    cudaStream_t s = stream_;
    const Layout layout = reserve(batches);
    for (int b = 0; b < batches; ++b)
      for (int i = 0; i < n; ++i)
        host_motions_.get()[std::size_t(b) * n + i] = labelMotion(twist_sets[std::size_t(b)][std::size_t(i)]);
    upload(motions_.get(), host_motions_.get(), std::size_t(batches) * n);
    enqueueSums(layout, nullptr, nullptr, false, batches);
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(host_sums_.get(), sums_.get(),
                                      std::size_t(batches) * layout.block_values * sizeof(double),
                                      cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    for (int b = 0; b < batches; ++b)
      unpack(layout, host_sums_.get() + std::size_t(b) * layout.block_values, out[std::size_t(b)], false);
  }

  void refitUnions(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& groups,
                   const std::vector<int>& batches, const std::vector<Vector6d>& starts, int iterations,
                   const Config& config, std::vector<UnionFit>& fits) override {
    refitOnDevice(twists, groups, batches, &starts, nullptr, iterations, config, fits);
  }

  bool refitPairs(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& pairs,
                  const std::vector<int>& batches, const std::vector<double>& own_cost, int iterations,
                  const Config& config, std::vector<UnionFit>& fits) override {
    if (pairs.empty()) {
      fits.clear();
      return true;
    }
    // More batches than one pass holds: the host chooses (refitPairsFromTheBetterMotion's loop) and refitUnions splits.
    if (*std::max_element(batches.begin(), batches.end()) + 1 > batchesPerPass()) return false;
    refitOnDevice(twists, pairs, batches, nullptr, &own_cost, iterations, config, fits);
    return true;
  }

 private:
  // refitUnions from `starts`, or (pairs only, `own_cost` given) from the better motion of each pair, chosen on the
  // device after a swapped pass (chooseUnionStarts): no host wait between the passes.
  void refitOnDevice(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& groups,
                     const std::vector<int>& batches, const std::vector<Vector6d>* starts_given,
                     const std::vector<double>* own_cost, int iterations, const Config& config,
                     std::vector<UnionFit>& fits) {
    if (level_.width <= 0) throw InputError("CUDA motion step: refitUnions() called before setLevel() or bind()");
    const std::vector<Vector6d> no_starts;
    const std::vector<Vector6d>& starts = starts_given ? *starts_given : no_starts;
    const int n = motion_labels_, group_count = int(groups.size());
    if (int(twists.size()) != n || (starts_given && starts.size() != groups.size()) ||
        (own_cost && int(own_cost->size()) != n) || batches.size() != groups.size())
      throw InputError("CUDA refitUnions: " + std::to_string(twists.size()) + " twists for " + std::to_string(n) +
                       " motion labels, " + std::to_string(starts.size()) + " starts, " +
                       std::to_string(own_cost ? own_cost->size() : 0) + " own costs and " +
                       std::to_string(batches.size()) + " batch numbers for " + std::to_string(group_count) +
                       " groups");
    fits.assign(groups.size(), UnionFit());
    if (n == 0 || group_count == 0) return;
    const int batch_count = *std::max_element(batches.begin(), batches.end()) + 1;
    const int per_pass = batchesPerPass();
    if (batch_count > per_pass) {  // a group's fit depends on its batch alone: ranges of batches one after the other
      for (int first = 0; first < batch_count; first += per_pass) {
        std::vector<std::vector<int>> part_groups;
        std::vector<int> part_batches, index;
        std::vector<Vector6d> part_starts;
        for (int g = 0; g < group_count; ++g)
          if (batches[std::size_t(g)] >= first && batches[std::size_t(g)] < first + per_pass) {
            if (!starts_given) throw InputError("CUDA refitPairs: more batches than one pass holds");
            part_groups.push_back(groups[std::size_t(g)]);
            part_batches.push_back(batches[std::size_t(g)] - first);
            part_starts.push_back(starts[std::size_t(g)]);
            index.push_back(g);
          }
        std::vector<UnionFit> part;
        refitOnDevice(twists, part_groups, part_batches, &part_starts, nullptr, iterations, config, part);
        for (std::size_t k = 0; k < index.size(); ++k) fits[std::size_t(index[k])] = std::move(part[k]);
      }
      return;
    }
    cudaStream_t s = stream_;
    const Layout layout = reserve(batch_count);
    // Up, in one staging buffer: per batch the motions at the starts (the other labels at their own twists) and each
    // label's group; each group's batch and state.
    const std::size_t slots = std::size_t(batch_count) * std::size_t(n);
    StagingLayout staged;
    const std::size_t motions_at = staged.add<LabelMotion>(slots), owner_at = staged.add<int>(slots),
                      batch_at = staged.add<int>(group_count), state_at = staged.add<UnionRefitState>(group_count),
                      cost_at = staged.add<double>(slots), swapped_at = own_cost ? staged.add<LabelMotion>(slots) : 0,
                      choice_at = own_cost ? staged.add<UnionStartChoice>(group_count) : 0;
    unsigned char* host = reserveStaging(staged);
    auto* motions = StagingLayout::at<LabelMotion>(host, motions_at);
    auto* group_of_label = StagingLayout::at<int>(host, owner_at);
    auto* batch_of_group = StagingLayout::at<int>(host, batch_at);
    auto* member_cost = StagingLayout::at<double>(host, cost_at);
    std::fill(group_of_label, group_of_label + slots, -1);
    std::fill(member_cost, member_cost + slots, 0.0);
    for (int g = 0; g < group_count; ++g) {
      const int b = batches[std::size_t(g)];
      if (b < 0 || b >= batch_count)
        throw InputError("CUDA refitUnions: group " + std::to_string(g) + " in batch " + std::to_string(b));
      batch_of_group[g] = b;
      for (const int i : groups[std::size_t(g)]) {
        int& owner = group_of_label[std::size_t(b) * n + i];
        if (owner >= 0)
          throw InputError("CUDA refitUnions: label " + std::to_string(i) + " in two groups of batch " +
                           std::to_string(b));
        owner = g;
      }
    }
    auto* state = StagingLayout::at<UnionRefitState>(host, state_at);
    if (!own_cost) {
      for (int b = 0; b < batch_count; ++b)
        for (int i = 0; i < n; ++i) {
          const int g = group_of_label[std::size_t(b) * n + i];
          motions[std::size_t(b) * n + i] = labelMotion(g >= 0 ? starts[std::size_t(g)] : twists[std::size_t(i)]);
        }
    } else {
      // The swapped table (each pair's motions exchanged) is both the cross pass's motions and, but for the members
      // that chooseUnionStarts overwrites, the refit's first pass's.
      auto* swapped = StagingLayout::at<LabelMotion>(host, swapped_at);
      auto* choice = StagingLayout::at<UnionStartChoice>(host, choice_at);
      std::vector<LabelMotion> own_motion(static_cast<std::size_t>(n));
      for (int i = 0; i < n; ++i) own_motion[std::size_t(i)] = labelMotion(twists[std::size_t(i)]);
      for (int b = 0; b < batch_count; ++b)
        for (int i = 0; i < n; ++i) swapped[std::size_t(b) * n + i] = own_motion[std::size_t(i)];
      for (int g = 0; g < group_count; ++g) {
        const std::vector<int>& pair = groups[std::size_t(g)];
        if (pair.size() != 2) throw InputError("CUDA refitPairs: group " + std::to_string(g) + " is not a pair");
        const int a = pair[0], b = pair[1];
        const std::size_t batch = std::size_t(batches[std::size_t(g)]) * n;
        swapped[batch + std::size_t(a)] = own_motion[std::size_t(b)];
        swapped[batch + std::size_t(b)] = own_motion[std::size_t(a)];
        UnionStartChoice& c = choice[g];
        c = UnionStartChoice{};
        c.a = a;
        c.b = b;
        c.own_a = (*own_cost)[std::size_t(a)];
        c.own_b = (*own_cost)[std::size_t(b)];
        for (int k = 0; k < 6; ++k) {
          c.twist_a[k] = twists[std::size_t(a)](k);
          c.twist_b[k] = twists[std::size_t(b)](k);
        }
      }
      std::copy_n(swapped, slots, motions);
    }
    for (int g = 0; g < group_count; ++g) {
      UnionRefitState& st = state[g];
      st = UnionRefitState{};
      if (!own_cost)
        for (int k = 0; k < 6; ++k) st.twist[k] = st.proposed[k] = starts[std::size_t(g)](k);
      st.damping = config.motion_damping;
    }
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(level_device_.get(), host, staged.bytes(), cudaMemcpyHostToDevice, s));
    unsigned char* device = level_device_.get();
    UnionRefitParams q;
    q.sums = sums_.get();
    q.batch_values = layout.block_values;
    q.batch_of_group = StagingLayout::at<int>(device, batch_at);
    q.group_of_label = StagingLayout::at<int>(device, owner_at);
    q.n = n;
    q.groups = group_count;
    q.min_damping = config.motion_damping;
    q.state = StagingLayout::at<UnionRefitState>(device, state_at);
    q.member_cost = StagingLayout::at<double>(device, cost_at);
    q.motions = StagingLayout::at<LabelMotion>(device, motions_at);
    const unsigned blocks = unsigned((group_count + 63) / 64);  // chooseUnionStarts: a thread per group
    const unsigned refit_blocks = unsigned((group_count + kRefitWarps - 1) / kRefitWarps);
    if (own_cost) {  // the swapped pass, then each pair's start: no wait
      const auto* swapped_device = StagingLayout::at<LabelMotion>(device, swapped_at);
      enqueueSums(layout, nullptr, swapped_device, false, batch_count);
      chooseUnionStarts<<<blocks, 64, 0, s>>>(sums_.get(), layout.block_values, q.batch_of_group, n, group_count,
                                              StagingLayout::at<UnionStartChoice>(device, choice_at), swapped_device,
                                              q.state, q.motions);
      MCFLOW_CUDA_CHECK_LAUNCH("chooseUnionStarts");
    }
    for (int pass = 0; pass <= iterations; ++pass) {
      enqueueSums(layout, nullptr, q.motions, false, batch_count);
      q.first = pass == 0;
      q.propose = pass < iterations;
      unionRefitStep<<<refit_blocks, kRefitWarps * 32, 0, s>>>(q);
      MCFLOW_CUDA_CHECK_LAUNCH("unionRefitStep");
    }
    // Down: the states and the members' costs (adjacent), one wait.
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(state, q.state, staged.bytes() - state_at, cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    for (int g = 0; g < group_count; ++g) {
      const UnionRefitState& st = state[g];
      UnionFit& f = fits[std::size_t(g)];
      for (int k = 0; k < 6; ++k) f.twist(k) = st.twist[k];
      int k = 0;
      for (int r = 0; r < 6; ++r)
        for (int c = r; c < 6; ++c, ++k) f.curvature(r, c) = f.curvature(c, r) = st.curvature[k];
      f.cost = st.cost;
      f.pixels = st.pixels;
      f.iterations = st.iterations;
      const std::size_t batch = std::size_t(batches[std::size_t(g)]) * n;
      for (const int i : groups[std::size_t(g)]) f.member_cost.push_back(member_cost[batch + std::size_t(i)]);
    }
  }

 public:
  bool iterateLevel(std::vector<Vector6d>& twists, const Config& config, MotionLevelStats& stats) override {
    if (level_.width <= 0) throw InputError("CUDA motion step: iterateLevel() called before setLevel() or bind()");
    const int n = motion_labels_;
    if (int(twists.size()) != n)
      throw InputError("CUDA motion step: " + std::to_string(twists.size()) + " twists for " + std::to_string(n) +
                       " motion labels");
    if (n == 0) return false;
    const auto start = std::chrono::steady_clock::now();
    cudaStream_t s = stream_;
    const Layout layout = reserve();
    const int iterations = config.motion_iterations_per_level;

    // Up: the linearisation points, the step control's start and the loop state, in one staging buffer.
    StagingLayout staged;
    const std::size_t motions_at = staged.add<LabelMotion>(n), control_at = staged.add<MotionLabelControl>(n),
                      twists_at = staged.add<double>(6 * std::size_t(n)), state_at = staged.add<IrlsState>(1);
    unsigned char* host = reserveStaging(staged);
    auto* motions = StagingLayout::at<LabelMotion>(host, motions_at);
    auto* control = StagingLayout::at<MotionLabelControl>(host, control_at);
    auto* xi = StagingLayout::at<double>(host, twists_at);
    auto* state = StagingLayout::at<IrlsState>(host, state_at);
    for (int i = 0; i < n; ++i) {
      motions[i] = labelMotion(twists[std::size_t(i)]);
      startMotionLabelControl(twists[std::size_t(i)].data(), config.motion_damping, control[i]);
      for (int k = 0; k < 6; ++k) xi[6 * i + k] = twists[std::size_t(i)](k);
    }
    *state = IrlsState{0, int(MotionStop::IterationLimit), 0, 0, 0, 0.0, 0.0};
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(level_device_.get(), host, staged.bytes(), cudaMemcpyHostToDevice, s));
    unsigned char* device = level_device_.get();

    StepParams q;
    q.sums = sums_.get();
    q.n = n;
    q.min_label_pixels = config.motion_min_label_pixels;
    q.min_damping = config.motion_damping;
    q.min_update = config.motion_min_update;
    q.min_coupling = config.motion_min_coupling;
    q.motions = StagingLayout::at<LabelMotion>(device, motions_at);
    q.control = StagingLayout::at<MotionLabelControl>(device, control_at);
    q.twists = StagingLayout::at<double>(device, twists_at);
    q.state = StagingLayout::at<IrlsState>(device, state_at);
    const std::size_t matrix_bytes = std::size_t(6 * n + 1) * std::size_t(6 * n + 1) * sizeof(double);
    const std::size_t panel_bytes = std::size_t(6 * n + 1) * 6 * sizeof(double);
    q.matrix_in_shared = matrix_bytes + panel_bytes + step_static_shared_ <= max_shared_bytes_;
    if (!q.matrix_in_shared) {
      step_matrix_.reserve(std::size_t(6 * n + 1) * std::size_t(6 * n + 1));
      q.matrix = step_matrix_.get();
    }
    const std::size_t step_shared = (q.matrix_in_shared ? matrix_bytes : 0) + panel_bytes;
    // Every iteration is queued at once: once the loop stops, the rest return at once (they read q.state->done).
    for (int iteration = 0; iteration < iterations; ++iteration) {
      enqueueSums(layout, &q.state->done, q.motions);
      q.iteration = iteration;
      q.last = iteration + 1 == iterations;
      irlsStep<<<1, kStepThreads, step_shared, s>>>(q);
      MCFLOW_CUDA_CHECK_LAUNCH("irlsStep");
    }
    // Down: the accepted twists and the state (the control array and the state are adjacent).
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(control, q.control, staged.bytes() - control_at, cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    for (int i = 0; i < n; ++i)
      for (int k = 0; k < 6; ++k) twists[std::size_t(i)](k) = control[i].accepted_twist[k];
    stats.iterations = state->iterations;
    stats.pixels_used = state->pixels_used;
    stats.cost_before = state->cost_before;
    stats.cost_after = state->cost_after;
    stats.stop = MotionStop(state->stop);
    stats.largest_block = state->largest_group;
    // The sums and the solves run together on the device: the loop's whole time is the accumulator's.
    stats.accumulate_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    stats.solve_ms = 0;
    return true;
  }

 private:
  // Sizes of one accumulation's sums.
  struct Layout {
    std::size_t pairs = 0, label_values = 0, block_values = 0, sum_values = 0, plane = 0, pair_chunks = 0;
    unsigned blocks = 0;
    int batches = 1;  // the batched passes reserved for
  };

  // Batched passes that one launch runs: as many as keep their block partials within kBatchPartialBytes.
  int batchesPerPass() const {
    const std::size_t plane = std::size_t(level_.width) * level_.height;
    const std::size_t batch_bytes =
        (plane + kThreads - 1) / kThreads * (std::size_t(motion_labels_) * kLabelStride + 2) * sizeof(double);
    // At most 65535: the batch is blockIdx.y.
    return int(std::min<std::size_t>(
        65535, std::max<std::size_t>(1, kBatchPartialBytes / std::max<std::size_t>(1, batch_bytes))));
  }

  // `batches`: how many batched passes (without the label pairs) the sums must hold.
  Layout reserve(int batches = 1) {
    const int n = motion_labels_;
    Layout l;
    l.pairs = std::size_t(n) * (n - 1) / 2;
    l.label_values = std::size_t(n) * kLabelStride;
    // Layout of the sums: per-label values, cost, pixels (block_values, as in the per-block partials), pairs.
    l.block_values = l.label_values + 2;
    l.sum_values = l.block_values + l.pairs * kUpper;
    l.plane = std::size_t(level_.width) * level_.height;
    l.blocks = unsigned((l.plane + kThreads - 1) / kThreads);
    l.pair_chunks = (l.plane + kPairChunkPixels - 1) / kPairChunkPixels;
    l.batches = batches;
    const std::size_t sum_values = std::max(l.sum_values, std::size_t(batches) * l.block_values);
    motions_.reserve(std::size_t(n) * std::size_t(batches));
    host_motions_.reserve(std::size_t(n) * std::size_t(batches));
    sums_.reserve(sum_values);
    host_sums_.reserve(sum_values);
    partials_.reserve(std::size_t(l.blocks) * l.block_values * std::size_t(batches));
    chunk_labels_.reserve(l.pair_chunks * kLabelMaskWords);
    if (l.pairs > 0) pair_partials_.reserve(l.pair_chunks * l.pairs * kUpper);
    return l;
  }

  // One pass at `twists` into `out`: with the label pairs' blocks (accumulate) or without (accumulateLabelBlocks).
  void accumulateSums(const std::vector<Vector6d>& twists, MotionNormalEquations& out, bool label_pairs) {
    if (level_.width <= 0) throw InputError("CUDA motion step: a pass requested before setLevel() or bind()");
    const int n = motion_labels_;
    if (int(twists.size()) != n)
      throw InputError("CUDA motion step: " + std::to_string(twists.size()) + " twists for " + std::to_string(n) +
                       " motion labels");
    out.reset(n);
    if (n == 0) return;
    cudaStream_t s = stream_;
    const Layout layout = reserve();
    for (int i = 0; i < n; ++i) host_motions_.get()[i] = labelMotion(twists[std::size_t(i)]);
    upload(motions_.get(), host_motions_.get(), std::size_t(n));
    enqueueSums(layout, nullptr, nullptr, label_pairs);
    const std::size_t values = label_pairs ? layout.sum_values : layout.block_values;
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(host_sums_.get(), sums_.get(), values * sizeof(double), cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    unpack(layout, host_sums_.get(), out, label_pairs);
  }

  // A label's linearisation point in float, as the CPU computes it.
  static LabelMotion labelMotion(const Vector6d& xi) {
    LabelMotion m;
    const cuda_detail::DeviceTransform T = cuda_detail::deviceTransform(xi);
    const Eigen::Matrix<float, 6, 6> J = se3LeftJacobian(xi).cast<float>();
    for (int k = 0; k < 12; ++k) m.transform[k] = T.m[k];
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) m.left_jacobian[r * 6 + c] = J(r, c);
    for (int k = 0; k < 6; ++k) m.twist[k] = xi(k);
    return m;
  }

  // Queues one accumulation at the motions in `motions` (default: motions_) into sums_; `skip` and `label_pairs` as
  // KernelParams (without the pairs, only sums_' first block_values are written). Without the pairs, `batches` passes
  // (at most the layout's) at batches sets of motions, one after the other in `motions`, into consecutive
  // block_values of sums_.
  void enqueueSums(const Layout& l, const int* skip, const LabelMotion* motions = nullptr, bool label_pairs = true,
                   int batches = 1) {
    if (batches < 1 || batches > l.batches || (label_pairs && batches != 1))
      throw InputError("CUDA motion step: " + std::to_string(batches) + " batched passes, " +
                       std::to_string(l.batches) + " reserved" + (label_pairs ? ", with the label pairs" : ""));
    cudaStream_t s = stream_;
    const int n = motion_labels_;
    KernelParams p;
    p.points1 = level_.points1;
    p.intensity1 = level_.intensity1;
    p.intensity2 = level_.intensity2;
    p.depth2 = level_.depth2;
    p.intensity_grad2 = level_.intensity_grad2;
    p.depth_grad2 = level_.depth_grad2;
    p.labels = bound_labels_;
    p.occluded = bound_occluded_;
    p.motions = motions ? motions : motions_.get();
    p.width = level_.width;
    p.height = level_.height;
    p.motion_labels = n;
    p.fx = float(level_.intrinsics.fx);
    p.fy = float(level_.intrinsics.fy);
    p.cx = float(level_.intrinsics.cx);
    p.cy = float(level_.intrinsics.cy);
    p.c_intensity = float(config_.cauchy_c_intensity);
    p.c_depth = float(config_.cauchy_c_depth);
    p.depth_noise_reference = float(config_.depth_noise_reference);
    p.alpha = float(config_.alpha);
    p.min_weight = float(config_.min_label_weight);
    p.out_of_view_cost = motionOutOfViewCost(config_);
    p.block_partials = partials_.get();
    p.blended = blended_.get();
    p.blended_hessian = blended_hessian_.get();
    p.active_mass = active_mass_.get();
    p.mass = mass_.get();
    p.skip = skip;

    // One shared-memory region per warp where they fit (the warps then reduce at once), else shared regions.
    const std::size_t region_bytes = l.block_values * sizeof(double);
    int regions = kWarps;
    while (regions > 1 && std::size_t(regions) * region_bytes > max_shared_bytes_) regions /= 2;
    const std::size_t shared_bytes = std::size_t(regions) * region_bytes;
    if (shared_bytes > max_shared_bytes_)
      throw BackendError("CUDA motion step: " + std::to_string(n) + " motion labels need " +
                         std::to_string(shared_bytes) + " bytes of shared memory, the device allows " +
                         std::to_string(max_shared_bytes_));
    p.sum_regions = regions;
    p.label_pairs = label_pairs;
    if (label_pairs)
      MCFLOW_CUDA_CHECK(
          cudaMemsetAsync(chunk_labels_.get(), 0, l.pair_chunks * kLabelMaskWords * sizeof(unsigned long long), s));
    p.chunk_labels = chunk_labels_.get();
    accumulateNormalEquations<<<dim3(l.blocks, unsigned(batches)), kThreads, shared_bytes, s>>>(p);
    MCFLOW_CUDA_CHECK_LAUNCH("accumulateNormalEquations");
    const unsigned reduce_blocks = unsigned((l.block_values * 32 + kThreads - 1) / kThreads);
    reduceBlockPartials<<<dim3(reduce_blocks, unsigned(batches)), kThreads, 0, s>>>(
        partials_.get(), int(l.blocks), int(l.block_values), sums_.get(), skip);
    MCFLOW_CUDA_CHECK_LAUNCH("reduceBlockPartials");
    if (label_pairs && l.pairs > 0) {
      const int chunks = int(l.pair_chunks);
      // One pair per block up to kPairBlocks blocks (a 320x240 level with up to 21 labels), beyond that several.
      const int pair_stride = int(std::min<long long>(l.pairs, std::max<long long>(1, kPairBlocks / chunks)));
      accumulatePairs<<<dim3(unsigned(chunks), unsigned(pair_stride)), kThreads, 0, s>>>(p, kPairChunkPixels,
                                                                                         pair_partials_.get());
      MCFLOW_CUDA_CHECK_LAUNCH("accumulatePairs");
      const unsigned add_blocks = unsigned((l.pairs * kUpper * 32 + kThreads - 1) / kThreads);
      cuda_detail::addChunksKernel<kUpper><<<add_blocks, kThreads, 0, s>>>(pair_partials_.get(), chunks, int(l.pairs),
                                                                           sums_.get() + l.block_values, skip);
      MCFLOW_CUDA_CHECK_LAUNCH("addChunksKernel (label pairs)");
    }
  }

  // `sums`: one pass's sums on the host; `label_pairs`: they hold the pairs' blocks (accumulate) or not
  // (accumulateLabelBlocks: those stay zero).
  void unpack(const Layout& l, const double* sums, MotionNormalEquations& out, bool label_pairs) {
    const int n = motion_labels_;
    const std::size_t label_values = l.label_values, block_values = l.block_values;
    // Unpack: symmetric diagonal blocks from their upper triangles, pair blocks into (a,b) and (b,a).
    auto fillSymmetric = [&out](const double* upper, int row0, int col0, bool mirror_block) {
      int k = 0;
      for (int r = 0; r < 6; ++r)
        for (int c = r; c < 6; ++c, ++k) {
          out.H(row0 + r, col0 + c) = upper[k];
          out.H(row0 + c, col0 + r) = upper[k];
          if (mirror_block) {
            out.H(col0 + r, row0 + c) = upper[k];
            out.H(col0 + c, row0 + r) = upper[k];
          }
        }
    };
    for (int i = 0; i < n; ++i) {
      const double* label = sums + std::size_t(i) * kLabelStride;
      fillSymmetric(label, 6 * i, 6 * i, false);
      for (int k = 0; k < 6; ++k) out.g(6 * i + k) = label[kUpper + k];
      out.label_cost(i) = label[kLabelCost];
      out.label_pixels(i) = label[kLabelPixels];
    }
    for (int a = 0; a < n && label_pairs; ++a)
      for (int b = a + 1; b < n; ++b) {
        const std::size_t pair = std::size_t(a) * n - std::size_t(a) * (a + 1) / 2 + std::size_t(b - a - 1);
        fillSymmetric(sums + block_values + pair * kUpper, 6 * a, 6 * b, true);
      }
    out.cost = sums[label_values];
    out.pixels = int(std::llround(sums[label_values + 1]));
  }

  template <typename T>
  void upload(T* device, const T* host, std::size_t count) {
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(device, host, count * sizeof(T), cudaMemcpyHostToDevice, stream_));
  }

  std::unique_ptr<cuda_detail::StreamHolder> own_stream_;
  cudaStream_t stream_ = nullptr;
  cuda_detail::DeviceLevel level_;
  const float* bound_labels_ = nullptr;
  const std::uint8_t* bound_occluded_ = nullptr;
  int motion_labels_ = 0;
  Config config_;
  DeviceBuffer<float> points1_, intensity1_, intensity2_, depth2_, intensity_grad2_, depth_grad2_, labels_;
  DeviceBuffer<float> blended_hessian_, active_mass_, mass_;  // blended pixels, for the pair kernel
  DeviceBuffer<std::uint8_t> occluded_, blended_;
  DeviceBuffer<LabelMotion> motions_;
  DeviceBuffer<double> sums_, partials_, pair_partials_;
  DeviceBuffer<unsigned long long> chunk_labels_;
  std::size_t max_shared_bytes_ = 48 * 1024;  // per block, opted in
  PinnedBuffer<LabelMotion> host_motions_;
  PinnedBuffer<double> host_sums_;
  // The device IRLS loop: its motions, step control, twists and state in one buffer, staged in one.
  // The host staging buffer and its device copy, grown to `layout`; returns the host one.
  unsigned char* reserveStaging(const StagingLayout& layout) {
    level_staging_.reserve(layout.bytes());
    level_device_.reserve(layout.bytes());
    return level_staging_.get();
  }

  PinnedBuffer<unsigned char> level_staging_;
  DeviceBuffer<unsigned char> level_device_;
  DeviceBuffer<double> step_matrix_;  // a group's matrix where it does not fit in shared memory
  std::size_t step_static_shared_ = 0;
};

}  // namespace

std::unique_ptr<MotionAccumulator> makeCudaMotionAccumulator() {
  std::string why;
  if (!cudaBackendAvailable(&why)) throw BackendError("CUDA motion step requested but unavailable: " + why);
  return std::make_unique<CudaMotionAccumulator>(nullptr);
}

namespace cuda_detail {
std::unique_ptr<DeviceMotionAccumulator> makeDeviceMotionAccumulator(cudaStream_t stream) {
  return std::make_unique<CudaMotionAccumulator>(stream);
}
}  // namespace cuda_detail

}  // namespace mc_flow
