// Label step on the GPU: the same diagonally preconditioned primal-dual iteration as
// src/core/label_optimization.cpp (the reference), one kernel per half-step.
//
// Arithmetic: the per-pixel rules (weights, data costs, step sizes, dual and primal updates) are the CPU's own,
// from include/mc_flow/core/label_step_pixel.h, every float operation rounded on its own (no FMAs), and the simplex
// projection is simplex_projection.h's. The iteration is therefore the CPU's operation for operation; the tests
// still allow a stated tolerance, for the day the two orders drift apart.
//
// Convergence: the CPU tests max |u_new - u_old| after every iteration; here the test needs a device
// reduction, so it runs every kConvergenceCheckInterval iterations and at the last one. With a tolerance the GPU
// may therefore run up to kConvergenceCheckInterval - 1 iterations more than the CPU; with tolerance <= 0 both run
// exactly `iterations` iterations. The test is decided on the device (checkConvergence): the rounds are queued
// without waiting (the host reads the stop flag only every kRoundsBetweenReads rounds, so a label step of the default
// 50 iterations waits once, at the end), and iterations queued after a converged round return at once.
#include <cuda_runtime.h>

#include <cub/device/device_reduce.cuh>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>

#include "cuda_check.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/label_step_pixel.h"
#include "mc_flow/core/simplex_projection.h"
#include "mc_flow/core/solve_backend.h"
#include "device_stages.h"

namespace mc_flow {

namespace {

using cuda_detail::DeviceBuffer;

constexpr int kMaxLabels = 128;  // these kernels' bound (the CPU has none); Config allows 65: 64 + outlier
constexpr int kConvergenceCheckInterval = 10;  // iterations between two max-change reductions
constexpr int kRoundsBetweenReads = 5;         // checked rounds queued between two host reads of the stop flag
constexpr int kBlockX = 32, kBlockY = 8;       // a warp spans 32 consecutive pixels of a row

// Rounded float operations that the compiler may not contract into FMAs (keeps the CPU's rounding).
__device__ __forceinline__ float sub(float a, float b) { return __fsub_rn(a, b); }
__device__ __forceinline__ float mul(float a, float b) { return __fmul_rn(a, b); }

// Diagonal preconditioners (label_pixel::stepSizes), stored in the form the iteration uses.
__global__ void computeStepSizes(const float* __restrict__ rx, const float* __restrict__ ry, int width, int height,
                                 bool tv, float lambda, float* __restrict__ sigma_rx, float* __restrict__ sigma_ry,
                                 float* __restrict__ shrink_x, float* __restrict__ shrink_y, float* __restrict__ tau) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x;
  const int y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= width || y >= height) return;
  const std::size_t i = std::size_t(y) * width + x;
  const label_pixel::StepSizes steps =
      label_pixel::stepSizes(rx[i], ry[i], x > 0 ? rx[i - 1] : 0.f, y > 0 ? ry[i - width] : 0.f, tv, lambda);
  sigma_rx[i] = steps.sigma_rx;
  sigma_ry[i] = steps.sigma_ry;
  shrink_x[i] = steps.shrink_x;
  shrink_y[i] = steps.shrink_y;
  tau[i] = steps.tau;
}

// Dual ascent + prox of sigma Q*; one thread per (pixel, label), label = blockIdx.z.
// At the last column/row sigma r = 0: the difference is not read there (0 stands for it).
__global__ void dualStep(const float* __restrict__ u_bar, float* __restrict__ p, const float* __restrict__ sigma_rx,
                         const float* __restrict__ sigma_ry, const float* __restrict__ shrink_x,
                         const float* __restrict__ shrink_y, int width, int height, bool tv, float inv_lambda,
                         const int* __restrict__ stopped) {
  if (*stopped) return;  // a queued iteration after convergence
  const int x = blockIdx.x * blockDim.x + threadIdx.x;
  const int y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= width || y >= height) return;
  const int label = blockIdx.z;
  const std::size_t plane = std::size_t(width) * height;
  const std::size_t i = std::size_t(y) * width + x;
  const float* ub = u_bar + label * plane;
  float* px = p + (2 * std::size_t(label)) * plane;
  float* py = px + plane;
  const float qx = label_pixel::dualAscent(px[i], sigma_rx[i], x + 1 < width ? sub(ub[i + 1], ub[i]) : 0.f);
  const float qy = label_pixel::dualAscent(py[i], sigma_ry[i], y + 1 < height ? sub(ub[i + width], ub[i]) : 0.f);
  if (tv) {
    const float scale = label_pixel::dualTvScale(qx, qy, inv_lambda);
    px[i] = mul(qx, scale);
    py[i] = mul(qy, scale);
  } else {
    px[i] = label_pixel::dualQuadratic(qx, shrink_x[i]);
    py[i] = label_pixel::dualQuadratic(qy, shrink_y[i]);
  }
}

// Primal descent + simplex projection + extrapolation. A block covers 32 consecutive pixels of a row; its
// blockDim.y threads per pixel share the labels (label = threadIdx.y, + blockDim.y, ...) for the descent and the
// extrapolation, and the first of them projects the pixel's n values onto the simplex. (One thread per pixel for
// everything left a 160x120 level with 19,200 threads, about four warps per multiprocessor: 11.5 us per call on
// an H100 under ncu, latency-bound.) The n candidate values sit in shared memory, label-major (a warp touches 32
// consecutive banks). Outlier-only pixels take the outlier label, and are extrapolated like every other pixel, as
// on the CPU. `change` (one float per pixel) receives max_i |u_new - u_old| when record_change is set (a max: the
// same bits in any order).
__global__ void primalStep(float* __restrict__ u, float* __restrict__ u_bar, const float* __restrict__ p,
                           const float* __restrict__ data_cost, const std::uint8_t* __restrict__ outlier_only,
                           const float* __restrict__ rx, const float* __restrict__ ry, const float* __restrict__ tau,
                           int width, int height, int count, bool record_change, float* __restrict__ change,
                           const int* __restrict__ stopped) {
  if (*stopped) return;  // a queued iteration after convergence (uniform: no barrier is skipped by part of the block)
  extern __shared__ float scratch[];  // count x 32 candidate values, then blockDim.y x 32 partial changes
  float* partial_change = scratch + count * kBlockX;
  const int x = blockIdx.x * kBlockX + threadIdx.x;
  const int y = blockIdx.y;
  const bool inside = x < width;  // every thread reaches the barriers below
  float* v = scratch + threadIdx.x;
  const std::size_t plane = std::size_t(width) * height;
  const std::size_t i = std::size_t(y) * width + (inside ? x : 0);
  const bool outlier = inside && outlier_only[i];
  if (inside && !outlier) {
    const float rx_here = rx[i], ry_here = ry[i], tau_here = tau[i];
    const float rx_left = x > 0 ? rx[i - 1] : 0.f, ry_up = y > 0 ? ry[i - width] : 0.f;
    for (int label = threadIdx.y; label < count; label += blockDim.y) {
      const float* px = p + (2 * std::size_t(label)) * plane;
      const float* py = px + plane;
      // K^T p = -(weighted backward divergence of p); zeros stand for the missing neighbours at the first column/row.
      const float divergence = label_pixel::divergence(rx_here, px[i], ry_here, py[i], rx_left, x > 0 ? px[i - 1] : 0.f,
                                                       ry_up, y > 0 ? py[i - width] : 0.f);
      v[label * kBlockX] =
          label_pixel::primalCandidate(u[label * plane + i], tau_here, divergence, data_cost[label * plane + i]);
    }
  }
  __syncthreads();
  if (inside && threadIdx.y == 0) {
    if (outlier) {
      for (int label = 0; label < count; ++label) v[label * kBlockX] = label == count - 1 ? 1.f : 0.f;
    } else {
      projectOntoSimplexStrided(v, count, kBlockX);
    }
  }
  __syncthreads();
  float max_change = 0.f;
  if (inside) {
    for (int label = threadIdx.y; label < count; label += blockDim.y) {
      const float old = u[label * plane + i];
      const float value = v[label * kBlockX];
      max_change = fmaxf(max_change, label_pixel::change(value, old));
      u[label * plane + i] = value;
      u_bar[label * plane + i] = label_pixel::extrapolate(value, old);
    }
  }
  if (!record_change) return;  // uniform: no barrier is skipped by part of the block
  partial_change[threadIdx.y * kBlockX + threadIdx.x] = max_change;
  __syncthreads();
  if (inside && threadIdx.y == 0) {
    for (int t = 1; t < int(blockDim.y); ++t) max_change = fmaxf(max_change, partial_change[t * kBlockX + threadIdx.x]);
    change[i] = max_change;
  }
}

// Per-pixel contribution to E(u) = sum_i <u_i, D_i> + lambda R(u), in double like labelEnergy().
__global__ void pixelEnergy(const float* __restrict__ u, const float* __restrict__ data_cost,
                            const float* __restrict__ rx, const float* __restrict__ ry, int width, int height,
                            int count, bool tv, double lambda, double* __restrict__ energy) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x;
  const int y = blockIdx.y * blockDim.y + threadIdx.y;
  if (x >= width || y >= height) return;
  const std::size_t plane = std::size_t(width) * height;
  const std::size_t i = std::size_t(y) * width + x;
  double sum = 0;
  for (int label = 0; label < count; ++label) {
    const float* ui = u + label * plane;
    sum += double(ui[i]) * data_cost[label * plane + i];
    const double qx = x + 1 < width ? double(mul(rx[i], sub(ui[i + 1], ui[i]))) : 0.0;
    const double qy = y + 1 < height ? double(mul(ry[i], sub(ui[i + width], ui[i]))) : 0.0;
    sum += lambda * (tv ? sqrt(qx * qx + qy * qy) : qx * qx + qy * qy);
  }
  energy[i] = sum;
}

// The state of a label step's iteration loop on the device.
struct LoopState {
  int stopped;        // 1 once a checked round's largest change fell below the tolerance
  int iterations;     // iterations run (the end of the last round that ran)
  float last_change;  // the largest change of the last checked iteration that ran
};

// After the checked iteration that ends a round at `round_end`: records it and stops the loop below the tolerance.
__global__ void checkConvergence(const float* __restrict__ max_change, double tolerance, int round_end,
                                 LoopState* __restrict__ state) {
  if (state->stopped) return;
  state->iterations = round_end;
  state->last_change = *max_change;
  if (double(*max_change) < tolerance) state->stopped = 1;
}

void validateProblem(const LabelProblem& problem, const SoftLabels& u) {
  const int W = problem.width, H = problem.height, n = problem.count;
  if (W <= 0 || H <= 0 || n < 1 || n > kMaxLabels)
    throw InputError("CUDA label step: problem size " + imageSizeText(W, H, n) + " is empty or has more than " +
                     std::to_string(kMaxLabels) + " labels");
  const std::size_t plane = std::size_t(W) * H;
  if (u.width != W || u.height != H || u.count != n)
    throw InputError("label step: labels are " + imageSizeText(u.width, u.height, u.count) + " but the problem is " +
                     imageSizeText(W, H, n));
  if (u.data.size() != plane * n)
    throw InputError("CUDA label step: soft-label buffer holds " + std::to_string(u.data.size()) +
                     " values, expected " + std::to_string(plane * n));
  if (problem.data_cost.size() != plane * n)
    throw InputError("CUDA label step: data_cost holds " + std::to_string(problem.data_cost.size()) +
                     " values, expected " + std::to_string(plane * n) + " (" + imageSizeText(W, H, n) + ")");
  auto requirePlane = [&](const char* name, int w, int h, std::size_t values) {
    if (w != W || h != H || values != plane)
      throw InputError(std::string("CUDA label step: ") + name + " is " + std::to_string(w) + "x" + std::to_string(h) +
                       " with " + std::to_string(values) + " values, expected " + std::to_string(W) + "x" +
                       std::to_string(H) + " with one channel");
  };
  requirePlane("weight_x", problem.weight_x.width, problem.weight_x.height, problem.weight_x.data.size());
  requirePlane("weight_y", problem.weight_y.width, problem.weight_y.height, problem.weight_y.data.size());
  requirePlane("outlier_only", problem.outlier_only.width, problem.outlier_only.height,
               problem.outlier_only.data.size());
}

struct PinnedScalars {
  LoopState loop{};
  double energy = 0.0;
};

// The iterations between two convergence checks run as one CUDA graph: at the coarse pyramid levels the
// solver works at (e.g. 160x120), a kernel takes a few microseconds and launch gaps would dominate.
struct GraphHolder {
  cudaGraphExec_t exec = nullptr;
  ~GraphHolder() { reset(); }
  void reset() {
    if (exec) cudaGraphExecDestroy(exec);
    exec = nullptr;
  }
};

// The primal-dual iteration on device-resident problems: the label step of cuda/solve_backend.cu, and the
// engine under CudaLabelOptimizer (the host-memory interface).
class PrimalDualEngine final : public cuda_detail::DevicePrimalDual {
 public:
  explicit PrimalDualEngine(cudaStream_t stream) : stream_(stream), scalars_(pinned_.reserve(1)) {}

  LabelStats run(const cuda_detail::DeviceLabelProblem& problem, float* u, float* p, int iterations,
                 double tolerance) override {
    const int W = problem.width, H = problem.height, n = problem.count;
    if (W <= 0 || H <= 0 || n < 1 || n > kMaxLabels)
      throw InputError("CUDA label step: problem size " + imageSizeText(W, H, n) + " is empty or has more than " +
                       std::to_string(kMaxLabels) + " labels");
    const std::size_t plane = std::size_t(W) * H;
    const bool tv = problem.regularizer == Regularizer::TotalVariation;
    cudaStream_t s = stream_;
    reserve(plane, n);
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(u_bar_.get(), u, plane * n * sizeof(float), cudaMemcpyDeviceToDevice, s));

    const Launch launch = makeLaunch(problem, u, p, tv);
    computeStepSizes<<<launch.grid, launch.block, 0, s>>>(problem.weight_x, problem.weight_y, W, H, tv,
                                                          float(problem.lambda), sigma_rx_.get(), sigma_ry_.get(),
                                                          shrink_x_.get(), shrink_y_.get(), tau_.get());
    MCFLOW_CUDA_CHECK_LAUNCH("computeStepSizes");

    // Iterations run in rounds that end with a checked iteration (one recording the change): every
    // kConvergenceCheckInterval-th with a tolerance, and always the last one (for stats.last_change). Rounds are queued
    // without waiting; checkConvergence stops the rest on the device.
    MCFLOW_CUDA_CHECK(cudaMemsetAsync(loop_state_.get(), 0, sizeof(LoopState), s));
    int done = 0, rounds_queued = 0;
    while (done < iterations) {
      const int round_end =
          tolerance > 0 ? std::min(iterations, (done / kConvergenceCheckInterval + 1) * kConvergenceCheckInterval)
                        : iterations;
      int unchecked = round_end - 1 - done;
      for (; unchecked >= kGraphIterations; unchecked -= kGraphIterations) {
        MCFLOW_CUDA_CHECK(cudaGraphLaunch(graphFor(launch), s));
      }
      for (; unchecked > 0; --unchecked) launchIteration(launch, false);
      launchIteration(launch, true);
      done = round_end;
      std::size_t bytes = temp_bytes_;
      MCFLOW_CUDA_CHECK_CUB(
          cub::DeviceReduce::Max(temp_.get(), bytes, change_.get(), max_change_.get(), int(plane), s));
      checkConvergence<<<1, 1, 0, s>>>(max_change_.get(), tolerance, round_end, loop_state_.get());
      MCFLOW_CUDA_CHECK_LAUNCH("checkConvergence");
      // A long loop (a large iteration limit with a tolerance) reads the flag now and then, so that a converged loop
      // does not leave thousands of queued iterations behind it (each a few microseconds even when it returns at once).
      if (++rounds_queued % kRoundsBetweenReads == 0 && done < iterations) {
        MCFLOW_CUDA_CHECK(
            cudaMemcpyAsync(&scalars_->loop, loop_state_.get(), sizeof(LoopState), cudaMemcpyDeviceToHost, s));
        MCFLOW_CUDA_WAIT(s);
        if (scalars_->loop.stopped) break;
      }
    }

    pixelEnergy<<<launch.grid, launch.block, 0, s>>>(u, problem.data_cost, problem.weight_x, problem.weight_y, W, H, n,
                                                     tv, problem.lambda, pixel_energy_.get());
    MCFLOW_CUDA_CHECK_LAUNCH("pixelEnergy");
    std::size_t bytes = temp_bytes_;
    MCFLOW_CUDA_CHECK_CUB(
        cub::DeviceReduce::Sum(temp_.get(), bytes, pixel_energy_.get(), energy_.get(), int(plane), s));
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(&scalars_->energy, energy_.get(), sizeof(double), cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(&scalars_->loop, loop_state_.get(), sizeof(LoopState), cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    LabelStats stats;
    stats.iterations = scalars_->loop.iterations;
    stats.last_change = scalars_->loop.last_change;
    stats.energy = scalars_->energy;
    return stats;
  }

 private:
  static constexpr int kGraphIterations = kConvergenceCheckInterval - 1;

  // Everything a launch of the iteration depends on; a cached graph is valid while this is unchanged.
  struct Launch {
    int width = 0, height = 0, count = 0;
    bool tv = false;
    float lambda = 0.f, inv_lambda = 0.f;
    dim3 block, grid, label_grid, primal_block, primal_grid;
    std::size_t primal_shared_bytes = 0;
    float* u = nullptr;
    float* p = nullptr;
    const float* data_cost = nullptr;
    const float* rx = nullptr;
    const float* ry = nullptr;
    const std::uint8_t* outlier_only = nullptr;
    const int* stopped = nullptr;  // the loop state's stop flag
    std::uint64_t buffers = 0;     // generation of the engine's buffers (pointers change when they grow)
    // `stopped` is not compared: it points into loop_state_, whose reallocation changes `buffers`.
    bool operator==(const Launch& o) const {
      return width == o.width && height == o.height && count == o.count && tv == o.tv && lambda == o.lambda &&
             u == o.u && p == o.p && data_cost == o.data_cost && rx == o.rx && ry == o.ry &&
             outlier_only == o.outlier_only && buffers == o.buffers;
    }
  };

  Launch makeLaunch(const cuda_detail::DeviceLabelProblem& problem, float* u, float* p, bool tv) {
    const int W = problem.width, H = problem.height, n = problem.count;
    Launch l;
    l.width = W;
    l.height = H;
    l.count = n;
    l.tv = tv;
    l.lambda = float(problem.lambda);
    l.inv_lambda = 1.f / l.lambda;  // the CPU multiplies by this float reciprocal
    l.u = u;
    l.p = p;
    l.data_cost = problem.data_cost;
    l.rx = problem.weight_x;
    l.ry = problem.weight_y;
    l.outlier_only = problem.outlier_only;
    l.stopped = &loop_state_.get()->stopped;
    l.buffers = buffer_generation_;
    l.block = dim3(kBlockX, kBlockY);
    l.grid = dim3((W + kBlockX - 1) / kBlockX, (H + kBlockY - 1) / kBlockY);
    l.label_grid = dim3(l.grid.x, l.grid.y, unsigned(n));
    // 32 pixels of a row per block, up to kPrimalLabelThreads threads per pixel sharing its labels; the shared scratch
    // is (n + those threads) x 32 floats (16.5 KiB at 128 labels).
    const int label_threads = std::min(n, kPrimalLabelThreads);
    l.primal_block = dim3(kBlockX, unsigned(label_threads));
    l.primal_grid = dim3((W + kBlockX - 1) / kBlockX, unsigned(H));
    l.primal_shared_bytes = (std::size_t(n) + std::size_t(label_threads)) * kBlockX * sizeof(float);
    if (l.primal_shared_bytes > primal_shared_limit_) {
      const cudaError_t status =
          cudaFuncSetAttribute(primalStep, cudaFuncAttributeMaxDynamicSharedMemorySize, int(l.primal_shared_bytes));
      if (status != cudaSuccess) {
        cudaGetLastError();
        throw BackendError("CUDA label step: " + std::to_string(n) + " labels need " +
                           std::to_string(l.primal_shared_bytes) + " bytes of shared memory per block, more than " +
                           "this GPU allows: " + cudaGetErrorString(status));
      }
      primal_shared_limit_ = l.primal_shared_bytes;
    }
    return l;
  }

  void launchIteration(const Launch& l, bool record_change) {
    cudaStream_t s = stream_;
    dualStep<<<l.label_grid, l.block, 0, s>>>(u_bar_.get(), l.p, sigma_rx_.get(), sigma_ry_.get(), shrink_x_.get(),
                                              shrink_y_.get(), l.width, l.height, l.tv, l.inv_lambda, l.stopped);
    MCFLOW_CUDA_CHECK_LAUNCH("dualStep");
    primalStep<<<l.primal_grid, l.primal_block, l.primal_shared_bytes, s>>>(
        l.u, u_bar_.get(), l.p, l.data_cost, l.outlier_only, l.rx, l.ry, tau_.get(), l.width, l.height, l.count,
        record_change, change_.get(), l.stopped);
    MCFLOW_CUDA_CHECK_LAUNCH("primalStep");
  }

  // The graph of kGraphIterations unchecked iterations for this launch configuration, captured on first use and kept
  // among the kGraphCache most recently used: a solve's label steps change the label count and swap the label buffers,
  // and the next pairs of a stream come back to the same configurations. (Capturing and instantiating a graph is host
  // work, counted by cudaCounters().graph_instantiations.)
  cudaGraphExec_t graphFor(const Launch& l) {
    ++graph_clock_;
    for (CachedGraph& cached : graphs_)
      if (cached.graph.exec && cached.launch == l) {
        cached.last_used = graph_clock_;
        return cached.graph.exec;
      }
    // A free slot, else the least recently used one.
    CachedGraph* slot = &graphs_[0];
    for (CachedGraph& cached : graphs_) {
      if (!cached.graph.exec) {
        slot = &cached;
        break;
      }
      if (cached.last_used < slot->last_used) slot = &cached;
    }
    slot->graph.reset();
    cudaStream_t s = stream_;
    MCFLOW_CUDA_CHECK(cudaStreamBeginCapture(s, cudaStreamCaptureModeThreadLocal));
    cudaGraph_t graph = nullptr;
    try {
      for (int k = 0; k < kGraphIterations; ++k) launchIteration(l, false);
    } catch (...) {
      cudaStreamEndCapture(s, &graph);  // leave capture mode before reporting the launch error
      if (graph) cudaGraphDestroy(graph);
      throw;
    }
    MCFLOW_CUDA_CHECK(cudaStreamEndCapture(s, &graph));
    const cudaError_t status = cudaGraphInstantiate(&slot->graph.exec, graph, 0);
    cudaGraphDestroy(graph);
    MCFLOW_CUDA_CHECK(status);
    cuda_detail::graph_instantiations.fetch_add(1, std::memory_order_relaxed);
    slot->launch = l;
    slot->last_used = graph_clock_;
    return slot->graph.exec;
  }

  template <typename T>
  void grow(DeviceBuffer<T>& buffer, std::size_t count) {
    if (count <= buffer.capacity()) return;
    buffer.reserve(count);
    ++buffer_generation_;
  }

  // Grows the buffers only when this call needs more than any earlier one.
  void reserve(std::size_t plane, int n) {
    const std::size_t labels = plane * std::size_t(n);
    grow(u_bar_, labels);
    grow(sigma_rx_, plane);
    grow(sigma_ry_, plane);
    grow(shrink_x_, plane);
    grow(shrink_y_, plane);
    grow(tau_, plane);
    grow(change_, plane);
    grow(pixel_energy_, plane);
    grow(max_change_, 1);
    grow(loop_state_, 1);
    grow(energy_, 1);
    if (plane > reduced_items_) {
      std::size_t max_bytes = 0, sum_bytes = 0;
      MCFLOW_CUDA_CHECK(cub::DeviceReduce::Max(nullptr, max_bytes, change_.get(), max_change_.get(), int(plane)));
      MCFLOW_CUDA_CHECK(cub::DeviceReduce::Sum(nullptr, sum_bytes, pixel_energy_.get(), energy_.get(), int(plane)));
      temp_bytes_ = std::max<std::size_t>(std::max(max_bytes, sum_bytes), 1);
      temp_.reserve(temp_bytes_);
      temp_bytes_ = temp_.capacity();
      reduced_items_ = plane;
    }
  }

  // Threads per pixel of the primal step. While one of them projects onto the simplex the others wait at the barrier
  // (ncu, H100, 13 labels at a 320x240 label level: barrier stalls half the kernel's, DRAM throughput 18 %); four per
  // pixel leave fewer warps waiting and more blocks per multiprocessor than eight: the label step of real 640x480
  // pairs 5-10 % faster (two rounds against eight and two; docs/decisions/0015). The results do not depend on it.
  static constexpr int kPrimalLabelThreads = 4;
  cudaStream_t stream_;
  cuda_detail::PinnedBuffer<PinnedScalars> pinned_;
  PinnedScalars* scalars_;  // what the host reads back: the loop state and the energy
  DeviceBuffer<float> u_bar_, sigma_rx_, sigma_ry_, shrink_x_, shrink_y_, tau_;
  DeviceBuffer<float> change_, max_change_;
  DeviceBuffer<LoopState> loop_state_;
  DeviceBuffer<std::uint8_t> temp_;
  DeviceBuffer<double> pixel_energy_, energy_;
  std::size_t temp_bytes_ = 0, reduced_items_ = 0;
  std::size_t primal_shared_limit_ = 48 * 1024;  // available without opting in
  std::uint64_t buffer_generation_ = 0;
  // Declared last: destroyed before the buffers they refer to.
  struct CachedGraph {
    GraphHolder graph;
    Launch launch;
    std::uint64_t last_used = 0;
  };
  static constexpr int kGraphCache = 16;
  std::array<CachedGraph, kGraphCache> graphs_;
  std::uint64_t graph_clock_ = 0;
};

// The host-memory interface: uploads the problem and the warm start, runs the engine, downloads u and p.
class CudaLabelOptimizer final : public LabelOptimizer {
 public:
  CudaLabelOptimizer() : engine_(stream_.stream) {}
  std::string name() const override { return "cuda"; }

  LabelStats optimize(const LabelProblem& problem, SoftLabels& u, LabelDual& dual, int iterations,
                      double tolerance) override {
    validateProblem(problem, u);
    const int W = problem.width, H = problem.height, n = problem.count;
    if (dual.width != W || dual.height != H || dual.count != n || dual.p.size() != std::size_t(W) * H * n * 2)
      dual.reset(W, H, n);
    const std::size_t plane = std::size_t(W) * H;
    cudaStream_t s = stream_.stream;
    data_cost_.reserve(plane * n);
    u_.reserve(plane * n);
    p_.reserve(plane * n * 2);
    rx_.reserve(plane);
    ry_.reserve(plane);
    outlier_only_.reserve(plane);
    upload(data_cost_.get(), problem.data_cost.data(), plane * n);
    upload(rx_.get(), problem.weight_x.ptr(), plane);
    upload(ry_.get(), problem.weight_y.ptr(), plane);
    upload(outlier_only_.get(), problem.outlier_only.ptr(), plane);
    upload(u_.get(), u.data.data(), plane * n);
    upload(p_.get(), dual.p.data(), plane * n * 2);
    const cuda_detail::DeviceLabelProblem device{
        W, H, n, data_cost_.get(), rx_.get(), ry_.get(), outlier_only_.get(), problem.regularizer, problem.lambda};
    const LabelStats stats = engine_.run(device, u_.get(), p_.get(), iterations, tolerance);
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(u.data.data(), u_.get(), plane * n * sizeof(float), cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(dual.p.data(), p_.get(), plane * n * 2 * sizeof(float), cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    return stats;
  }

 private:
  template <typename T>
  void upload(T* device, const T* host, std::size_t count) {
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(device, host, count * sizeof(T), cudaMemcpyHostToDevice, stream_.stream));
  }

  cuda_detail::StreamHolder stream_;
  DeviceBuffer<float> data_cost_, u_, p_, rx_, ry_;
  DeviceBuffer<std::uint8_t> outlier_only_;
  PrimalDualEngine engine_;  // declared last: destroyed before the stream and the buffers it ran on
};

// ----------------------------------------------------------------- data costs and weights (device-resident solve)
__global__ void geometricWeightsKernel(const cuda_detail::DeviceImage points, float fmean, float wmin,
                                       float* __restrict__ weight_x, float* __restrict__ weight_y) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  const int W = points.width, H = points.height;
  if (x >= W || y >= H) return;
  auto weight = [&](int x1, int y1) {
    return label_pixel::geometricWeight(points.at(x, y, 0), points.at(x, y, 1), points.at(x, y, 2),
                                        points.at(x1, y1, 0), points.at(x1, y1, 1), points.at(x1, y1, 2), fmean, wmin);
  };
  const std::size_t i = std::size_t(y) * W + x;
  weight_x[i] = x + 1 < W ? weight(x + 1, y) : 0.f;
  weight_y[i] = y + 1 < H ? weight(x, y + 1) : 0.f;
}

struct DataCostParams {
  cuda_detail::DeviceLevel level;
  const cuda_detail::DeviceTransform* transforms;
  int motion_labels;
  const std::uint8_t* occluded;
  label_pixel::DataCostTerms terms;
  float outlier_cost;
};

__global__ void dataCostsKernel(const DataCostParams q, float* __restrict__ data_cost,
                                std::uint8_t* __restrict__ outlier_only) {
  const int x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
  const int W = q.level.width, H = q.level.height;
  if (x >= W || y >= H) return;
  const std::size_t plane = std::size_t(W) * H, idx = std::size_t(y) * W + x;
  const int n = q.motion_labels + 1;
  const float P[3] = {q.level.points1.at(x, y, 0), q.level.points1.at(x, y, 1), q.level.points1.at(x, y, 2)};
  if (!isfinite(P[2])) {
    outlier_only[idx] = 1;
    for (int i = 0; i < n; ++i) data_cost[i * plane + idx] = 0.f;
    return;
  }
  outlier_only[idx] = 0;
  if (q.occluded && q.occluded[idx]) {  // section 6: no data term, the regulariser decides
    for (int i = 0; i < n; ++i) data_cost[i * plane + idx] = 0.f;
    return;
  }
  data_cost[std::size_t(q.motion_labels) * plane + idx] = q.outlier_cost;
  const float I1 = q.level.intensity1.at(x, y, 0);
  for (int i = 0; i < q.motion_labels; ++i) {
    float P2[3];
    transformPoint(q.transforms[i].m, P, P2);
    data_cost[std::size_t(i) * plane + idx] =
        label_pixel::motionLabelCost(P2, I1, cuda_detail::DeviceChannel{q.level.intensity2, 0},
                                     cuda_detail::DeviceChannel{q.level.depth2, 0}, W, H, q.terms);
  }
}

}  // namespace

bool cudaBackendAvailable(std::string* why, int requested_device) {
  int count = 0;
  const cudaError_t status = cudaGetDeviceCount(&count);
  if (status != cudaSuccess) {
    cudaGetLastError();  // clear the (non-sticky) error so later runtime calls start clean
    if (why)
      *why = std::string("cudaGetDeviceCount failed: ") + cudaGetErrorName(status) + " (" +
             std::to_string(int(status)) + "): " + cudaGetErrorString(status);
    return false;
  }
  if (count <= 0) {
    if (why) *why = "cudaGetDeviceCount found " + std::to_string(count) + " CUDA devices";
    return false;
  }
  if (requested_device < 0 || requested_device >= count) {
    if (why)
      *why = "CUDA device " + std::to_string(requested_device) + " requested (cuda_device), but " +
             std::to_string(count) + " CUDA device" + (count == 1 ? " is" : "s are") + " present (0.." +
             std::to_string(count - 1) + ")";
    return false;
  }
  const int device = requested_device;
  cudaDeviceProp properties{};
  if (cudaGetDeviceProperties(&properties, device) != cudaSuccess) {
    const cudaError_t error = cudaGetLastError();
    if (why) *why = "cannot query CUDA device " + std::to_string(device) + ": " + cudaGetErrorString(error);
    return false;
  }
  // A build without code for this GPU's architecture fails only at the first launch: ask now. The question is
  // answered for the current device, so that device is made current for it and the caller's is restored.
  int previous = 0;
  cudaFuncAttributes attributes{};
  cudaError_t kernel_status = cudaGetDevice(&previous);
  if (kernel_status == cudaSuccess) kernel_status = cudaSetDevice(device);
  if (kernel_status == cudaSuccess) kernel_status = cudaFuncGetAttributes(&attributes, primalStep);
  if (previous != device) cudaSetDevice(previous);
  if (kernel_status != cudaSuccess) {
    cudaGetLastError();
    if (why)
      *why = std::string("this build has no kernels for ") + properties.name + " (compute capability " +
             std::to_string(properties.major) + "." + std::to_string(properties.minor) +
             "): " + cudaGetErrorString(kernel_status);
    return false;
  }
  if (why)
    *why = std::string("CUDA device ") + std::to_string(device) + ": " + properties.name + " (compute capability " +
           std::to_string(properties.major) + "." + std::to_string(properties.minor) + ")";
  return true;
}

std::unique_ptr<LabelOptimizer> makeCudaLabelOptimizer() {
  std::string why;
  if (!cudaBackendAvailable(&why)) throw BackendError("CUDA backend requested but unavailable: " + why);
  return std::make_unique<CudaLabelOptimizer>();
}

namespace cuda_detail {

std::unique_ptr<DevicePrimalDual> makeDevicePrimalDual(cudaStream_t stream) {
  return std::make_unique<PrimalDualEngine>(stream);
}

void launchGeometricWeights(const DeviceLevel& level, double min_weight, float* weight_x, float* weight_y,
                            cudaStream_t stream) {
  const dim3 block(kBlockX, kBlockY),
      grid((level.width + kBlockX - 1) / kBlockX, (level.height + kBlockY - 1) / kBlockY);
  const float fmean = label_pixel::geometricWeightFocal(level.intrinsics);
  geometricWeightsKernel<<<grid, block, 0, stream>>>(level.points1, fmean, float(min_weight), weight_x, weight_y);
  MCFLOW_CUDA_CHECK_LAUNCH("geometricWeightsKernel");
}

void launchDataCosts(const DeviceLevel& level, const DeviceTransform* transforms, int motion_labels,
                     const std::uint8_t* occluded, const Config& config, float* data_cost, std::uint8_t* outlier_only,
                     cudaStream_t stream) {
  DataCostParams q;
  q.level = level;
  q.transforms = transforms;
  q.motion_labels = motion_labels;
  q.occluded = occluded;
  q.terms = label_pixel::dataCostTerms(level.intrinsics, config);
  q.outlier_cost = float(config.outlier_cost);
  const dim3 block(kBlockX, kBlockY),
      grid((level.width + kBlockX - 1) / kBlockX, (level.height + kBlockY - 1) / kBlockY);
  dataCostsKernel<<<grid, block, 0, stream>>>(q, data_cost, outlier_only);
  MCFLOW_CUDA_CHECK_LAUNCH("dataCostsKernel");
}

namespace {

__global__ void addSwitchingCostKernel(const int* __restrict__ carried, float cost, std::size_t plane, int count,
                                       const std::uint8_t* __restrict__ outlier_only, float* __restrict__ data_cost) {
  const std::size_t idx = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (idx >= plane) return;
  const int own = carried[idx];
  if (own < 0 || outlier_only[idx]) return;
  for (int i = 0; i < count; ++i)
    if (i != own) data_cost[std::size_t(i) * plane + idx] = __fadd_rn(data_cost[std::size_t(i) * plane + idx], cost);
}

struct SwitchingPixel {
  const float* u;
  const int* carried;
  const std::uint8_t* outlier_only;
  std::size_t plane;
  __device__ void operator()(int, std::size_t k, double* sums) const {
    const int own = carried[k];
    if (own >= 0 && !outlier_only[k]) sums[0] += 1.0 - double(u[std::size_t(own) * plane + k]);
  }
};

}  // namespace

void launchSwitchingShare(const float* u, const int* carried, const std::uint8_t* outlier_only, std::size_t plane,
                          DeviceBuffer<double>& scratch, double* out, cudaStream_t stream) {
  launchChunkSums<1>(SwitchingPixel{u, carried, outlier_only, plane}, plane, 1, scratch, out, stream,
                     "switching energy");
}

void launchAddSwitchingCost(const int* carried, float cost, std::size_t plane, int count,
                            const std::uint8_t* outlier_only, float* data_cost, cudaStream_t stream) {
  addSwitchingCostKernel<<<unsigned((plane + 255) / 256), 256, 0, stream>>>(carried, cost, plane, count, outlier_only,
                                                                            data_cost);
  MCFLOW_CUDA_CHECK_LAUNCH("addSwitchingCostKernel");
}

}  // namespace cuda_detail

}  // namespace mc_flow
