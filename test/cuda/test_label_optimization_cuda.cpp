// CUDA label step against the CPU reference (src/core/label_optimization.cpp).
//
// Tolerances. The CUDA kernels perform the CPU's float operations in the CPU's order with explicitly
// rounded intrinsics (no FMA contraction), so the two normally agree bit for bit. We still allow
// kLabelTolerance = 1e-4 on u (and a relative 1e-4 on the energy): should a compiler on either side round one
// operation differently (e.g. an FMA on a CPU built with -march=native), each iteration adds an error of a few
// float ulps (~1e-7 for values in [0, 1]); the primal-dual map is non-expansive and the simplex projection
// 1-Lipschitz, so the errors add up rather than grow: 150 iterations x ~5e-7 < 1e-4. The observed
// differences are recorded as test properties (max_abs_u_difference) in the XML output.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/solve_backend.h"

namespace mc_flow {
namespace {

constexpr double kLabelTolerance = 1e-4;
constexpr double kEnergyRelativeTolerance = 1e-4;
constexpr double kSimplexTolerance = 1e-5;  // sum over <= 21 float values of ~1/n each: a few ulps of 1
constexpr int kIterations = 150;            // Config::label_iterations

bool gpuUsable(std::string* why) { return cudaBackendAvailable(why); }

#define SKIP_WITHOUT_GPU()                                                                   \
  do {                                                                                       \
    std::string why_no_gpu;                                                                  \
    if (!gpuUsable(&why_no_gpu)) GTEST_SKIP() << "CUDA backend unavailable: " << why_no_gpu; \
  } while (0)

// Data costs with structure: a few regions (Voronoi cells of random seeds), each cheap for one label,
// plus noise; the outlier label has a constant cost. Weights are random in (0, 1] with some tiny ones
// (the geometric-weight floor 1e-3 and below) and 0 at the last column/row as the interface requires.
// Some pixels are outlier-only (scattered, plus a block).
LabelProblem makeProblem(int width, int height, int count, Regularizer regularizer, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  LabelProblem problem;
  problem.width = width;
  problem.height = height;
  problem.count = count;
  problem.regularizer = regularizer;
  problem.lambda = regularizer == Regularizer::Quadratic ? 4.0 : 1.0;
  const std::size_t plane = std::size_t(width) * height;
  problem.data_cost.assign(plane * count, 0.f);
  problem.weight_x = ImageF(width, height, 1, 0.f);
  problem.weight_y = ImageF(width, height, 1, 0.f);
  problem.outlier_only = ImageU8(width, height, 1, 0);

  const int regions = 6;
  std::vector<float> seed_x(regions), seed_y(regions);
  std::vector<int> region_label(regions);
  for (int r = 0; r < regions; ++r) {
    seed_x[r] = unit(rng) * width;
    seed_y[r] = unit(rng) * height;
    region_label[r] = count > 1 ? int(rng() % unsigned(count - 1)) : 0;
  }
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const std::size_t i = std::size_t(y) * width + x;
      int nearest = 0;
      float best = 1e30f;
      for (int r = 0; r < regions; ++r) {
        const float d = (x - seed_x[r]) * (x - seed_x[r]) + (y - seed_y[r]) * (y - seed_y[r]);
        if (d < best) best = d, nearest = r;
      }
      for (int label = 0; label + 1 < count; ++label) {
        const float base = label == region_label[nearest] ? 0.5f : 2.5f + 2.f * unit(rng);
        problem.data_cost[label * plane + i] = base + 1.5f * unit(rng);
      }
      problem.data_cost[(count - 1) * plane + i] = 3.5f;  // K_D

      const float draw = unit(rng);
      auto weight = [&](float d) { return d < 0.05f ? 1e-3f : d < 0.08f ? 1e-6f : 0.05f + 0.95f * unit(rng); };
      if (x + 1 < width) problem.weight_x(x, y) = weight(draw);
      if (y + 1 < height) problem.weight_y(x, y) = weight(unit(rng));
      const bool in_block = x >= width / 3 && x < width / 3 + 5 && y >= height / 2 && y < height / 2 + 4;
      if (in_block || unit(rng) < 0.02f) problem.outlier_only(x, y) = 1;
    }
  }
  return problem;
}

// A random warm start on the simplex and a random dual variable.
void makeWarmStart(const LabelProblem& problem, unsigned seed, SoftLabels& u, LabelDual& dual) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  u = SoftLabels(problem.width, problem.height, problem.count);
  const std::size_t plane = u.planeSize();
  for (std::size_t i = 0; i < plane; ++i) {
    float sum = 0.f;
    for (int label = 0; label < u.count; ++label) sum += (u.data[label * plane + i] = 0.05f + unit(rng));
    for (int label = 0; label < u.count; ++label) u.data[label * plane + i] /= sum;
  }
  dual.reset(problem.width, problem.height, problem.count);
  for (float& v : dual.p) v = 0.2f * (unit(rng) - 0.5f);
}

double maxAbsDifference(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double worst = 0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    worst = std::max(worst, double(std::fabs(a[i] - b[i])));
  return worst;
}

void expectOnSimplex(const SoftLabels& u) {
  const std::size_t plane = u.planeSize();
  double worst_sum = 0, most_negative = 0;
  for (std::size_t i = 0; i < plane; ++i) {
    double sum = 0;
    for (int label = 0; label < u.count; ++label) {
      const float v = u.data[label * plane + i];
      ASSERT_TRUE(std::isfinite(v)) << "label " << label << " pixel " << i;
      most_negative = std::min(most_negative, double(v));
      sum += v;
    }
    worst_sum = std::max(worst_sum, std::fabs(sum - 1.0));
  }
  EXPECT_GE(most_negative, 0.0);
  EXPECT_LT(worst_sum, kSimplexTolerance);
}

struct Case {
  int width, height, count;
  Regularizer regularizer;
};

std::string caseName(const ::testing::TestParamInfo<Case>& info) {
  const Case& c = info.param;
  return std::to_string(c.width) + "x" + std::to_string(c.height) + "_n" + std::to_string(c.count) + "_" +
         (c.regularizer == Regularizer::Quadratic ? "quadratic" : "tv");
}

class CudaLabelStepMatchesCpu : public ::testing::TestWithParam<Case> {};

TEST_P(CudaLabelStepMatchesCpu, FixedIterationsToleranceZero) {
  SKIP_WITHOUT_GPU();
  const Case c = GetParam();
  const LabelProblem problem = makeProblem(c.width, c.height, c.count, c.regularizer, 7u + unsigned(c.count));
  SoftLabels u_start;
  LabelDual p_start;
  makeWarmStart(problem, 11u, u_start, p_start);

  SoftLabels u_cpu = u_start, u_gpu = u_start;
  LabelDual p_cpu = p_start, p_gpu = p_start;
  const LabelStats cpu = makeCpuLabelOptimizer()->optimize(problem, u_cpu, p_cpu, kIterations, 0.0);
  const LabelStats gpu = makeCudaLabelOptimizer()->optimize(problem, u_gpu, p_gpu, kIterations, 0.0);

  EXPECT_EQ(cpu.iterations, kIterations);
  EXPECT_EQ(gpu.iterations, kIterations);
  const double du = maxAbsDifference(u_gpu.data, u_cpu.data);
  const double dp = maxAbsDifference(p_gpu.p, p_cpu.p);
  RecordProperty("max_abs_u_difference", std::to_string(du));
  RecordProperty("max_abs_p_difference", std::to_string(dp));
  EXPECT_LT(du, kLabelTolerance);
  EXPECT_LT(dp, kLabelTolerance * problem.lambda);  // p lives on the scale of lambda
  EXPECT_NEAR(gpu.last_change, cpu.last_change, kLabelTolerance);
  EXPECT_NEAR(gpu.energy, cpu.energy, kEnergyRelativeTolerance * std::fabs(cpu.energy));
  expectOnSimplex(u_gpu);
  // The solve did something: otherwise equality above would prove nothing.
  EXPECT_GT(maxAbsDifference(u_gpu.data, u_start.data), 0.1);
  // Outlier-only pixels hold the outlier label exactly.
  const std::size_t plane = u_gpu.planeSize();
  for (std::size_t i = 0; i < plane; ++i)
    if (problem.outlier_only.data[i]) {
      ASSERT_EQ(u_gpu.data[(c.count - 1) * plane + i], 1.f) << "pixel " << i;
    }
}

INSTANTIATE_TEST_SUITE_P(
    AwkwardSizes, CudaLabelStepMatchesCpu,
    ::testing::Values(Case{37, 23, 2, Regularizer::Quadratic}, Case{37, 23, 5, Regularizer::TotalVariation},
                      Case{37, 23, 21, Regularizer::Quadratic}, Case{37, 23, 21, Regularizer::TotalVariation},
                      Case{131, 97, 2, Regularizer::TotalVariation}, Case{131, 97, 5, Regularizer::Quadratic},
                      Case{131, 97, 21, Regularizer::TotalVariation}, Case{631, 479, 2, Regularizer::Quadratic},
                      Case{631, 479, 5, Regularizer::TotalVariation}, Case{631, 479, 21, Regularizer::Quadratic},
                      Case{631, 479, 21, Regularizer::TotalVariation}, Case{1, 1, 2, Regularizer::Quadratic},
                      Case{1, 57, 5, Regularizer::TotalVariation}, Case{64, 33, 65, Regularizer::Quadratic},
                      Case{37, 23, 128, Regularizer::TotalVariation}),
    caseName);

// With zero iterations the GPU returns the warm start unchanged and the energy of it, which must equal the
// CPU's labelEnergy (both sum in double: only the summation order differs).
TEST(CudaLabelStep, EnergyOfWarmStartMatchesLabelEnergy) {
  SKIP_WITHOUT_GPU();
  for (Regularizer regularizer : {Regularizer::Quadratic, Regularizer::TotalVariation}) {
    const LabelProblem problem = makeProblem(131, 97, 5, regularizer, 3u);
    SoftLabels u, u_start;
    LabelDual p, p_start;
    makeWarmStart(problem, 5u, u_start, p_start);
    u = u_start;
    p = p_start;
    const LabelStats stats = makeCudaLabelOptimizer()->optimize(problem, u, p, 0, 0.0);
    EXPECT_EQ(stats.iterations, 0);
    EXPECT_EQ(u.data, u_start.data);
    EXPECT_EQ(p.p, p_start.p);
    const double expected = labelEnergy(problem, u_start);
    EXPECT_NEAR(stats.energy, expected, 1e-9 * std::fabs(expected));
  }
}

// With a tolerance the GPU checks convergence every 10 iterations (the CPU every iteration): it stops, no
// earlier than the CPU, at a checked iteration whose change is below the tolerance, and its result is the
// CPU's after the same number of iterations.
TEST(CudaLabelStep, StopsAtTolerance) {
  SKIP_WITHOUT_GPU();
  const double tolerance = 1e-3;
  const int max_iterations = 3000;
  for (Regularizer regularizer : {Regularizer::Quadratic, Regularizer::TotalVariation}) {
    SCOPED_TRACE(regularizer == Regularizer::Quadratic ? "quadratic" : "tv");
    const LabelProblem problem = makeProblem(131, 97, 5, regularizer, 21u);
    SoftLabels u_start;
    LabelDual p_start;
    makeWarmStart(problem, 23u, u_start, p_start);

    SoftLabels u_cpu = u_start, u_gpu = u_start;
    LabelDual p_cpu = p_start, p_gpu = p_start;
    const LabelStats cpu = makeCpuLabelOptimizer()->optimize(problem, u_cpu, p_cpu, max_iterations, tolerance);
    const LabelStats gpu = makeCudaLabelOptimizer()->optimize(problem, u_gpu, p_gpu, max_iterations, tolerance);
    ASSERT_LT(cpu.iterations, max_iterations) << "the CPU did not converge: the test problem is too hard";
    EXPECT_LT(gpu.iterations, max_iterations);
    EXPECT_LT(gpu.last_change, tolerance);
    EXPECT_EQ(gpu.iterations % 10, 0);
    EXPECT_GE(gpu.iterations, cpu.iterations);
    RecordProperty(regularizer == Regularizer::Quadratic ? "iterations_quadratic" : "iterations_tv",
                   std::to_string(cpu.iterations) + " cpu, " + std::to_string(gpu.iterations) + " gpu");

    // Same iteration count on the CPU reproduces the GPU result.
    SoftLabels u_same = u_start;
    LabelDual p_same = p_start;
    makeCpuLabelOptimizer()->optimize(problem, u_same, p_same, gpu.iterations, 0.0);
    EXPECT_LT(maxAbsDifference(u_gpu.data, u_same.data), kLabelTolerance);

    // Close to where the CPU stopped: each extra iteration moved u by about the tolerance at most.
    const int extra = gpu.iterations - cpu.iterations;
    const double bound = (extra + 1) * tolerance + kLabelTolerance;
    EXPECT_LT(maxAbsDifference(u_gpu.data, u_cpu.data), bound) << extra << " extra iterations";
    EXPECT_NEAR(gpu.energy, cpu.energy, 1e-3 * std::fabs(cpu.energy));
    expectOnSimplex(u_gpu);
  }
}

// A tolerance that is never reached: the GPU runs exactly the iteration limit (here not a multiple of the
// check interval) and matches the CPU.
TEST(CudaLabelStep, TolerancePathStopsAtIterationLimit) {
  SKIP_WITHOUT_GPU();
  const LabelProblem problem = makeProblem(131, 97, 21, Regularizer::TotalVariation, 51u);
  SoftLabels u_start;
  LabelDual p_start;
  makeWarmStart(problem, 53u, u_start, p_start);
  for (int iterations : {1, 9, 25}) {
    SCOPED_TRACE(std::to_string(iterations) + " iterations");
    SoftLabels u_cpu = u_start, u_gpu = u_start;
    LabelDual p_cpu = p_start, p_gpu = p_start;
    const LabelStats cpu = makeCpuLabelOptimizer()->optimize(problem, u_cpu, p_cpu, iterations, 1e-30);
    const LabelStats gpu = makeCudaLabelOptimizer()->optimize(problem, u_gpu, p_gpu, iterations, 1e-30);
    EXPECT_EQ(cpu.iterations, iterations);
    EXPECT_EQ(gpu.iterations, iterations);
    EXPECT_NEAR(gpu.last_change, cpu.last_change, kLabelTolerance);
    EXPECT_LT(maxAbsDifference(u_gpu.data, u_cpu.data), kLabelTolerance);
    EXPECT_LT(maxAbsDifference(p_gpu.p, p_cpu.p), kLabelTolerance * problem.lambda);
  }
}

// One optimizer, several sizes and label counts in turn: buffers grow or are reused, results stay right,
// and repeating a call gives the same result (nothing left over from the previous call).
TEST(CudaLabelStep, ReusesBuffersAcrossSizes) {
  SKIP_WITHOUT_GPU();
  auto gpu_optimizer = makeCudaLabelOptimizer();
  auto cpu_optimizer = makeCpuLabelOptimizer();
  const Case cases[] = {{131, 97, 5, Regularizer::Quadratic},
                        {37, 23, 21, Regularizer::TotalVariation},
                        {320, 240, 3, Regularizer::TotalVariation},
                        {131, 97, 5, Regularizer::Quadratic}};
  std::vector<float> first_result;
  for (std::size_t k = 0; k < std::size(cases); ++k) {
    const Case& c = cases[k];
    SCOPED_TRACE(std::to_string(c.width) + "x" + std::to_string(c.height) + "x" + std::to_string(c.count));
    const LabelProblem problem = makeProblem(c.width, c.height, c.count, c.regularizer, 31u);
    SoftLabels u_start;
    LabelDual p_start;
    makeWarmStart(problem, 37u, u_start, p_start);
    SoftLabels u_cpu = u_start, u_gpu = u_start;
    LabelDual p_cpu = p_start, p_gpu = p_start;
    cpu_optimizer->optimize(problem, u_cpu, p_cpu, 60, 0.0);
    const LabelStats stats = gpu_optimizer->optimize(problem, u_gpu, p_gpu, 60, 0.0);
    EXPECT_EQ(stats.iterations, 60);
    EXPECT_LT(maxAbsDifference(u_gpu.data, u_cpu.data), kLabelTolerance);
    EXPECT_LT(maxAbsDifference(p_gpu.p, p_cpu.p), kLabelTolerance * problem.lambda);
    if (k == 0) first_result = u_gpu.data;
    if (k + 1 == std::size(cases)) {
      EXPECT_EQ(u_gpu.data, first_result);
    }
  }
}

// A dual variable of the wrong size is reset to zero, as on the CPU.
TEST(CudaLabelStep, ResetsMismatchedDualLikeCpu) {
  SKIP_WITHOUT_GPU();
  const LabelProblem problem = makeProblem(37, 23, 5, Regularizer::TotalVariation, 41u);
  SoftLabels u_start;
  LabelDual unused;
  makeWarmStart(problem, 43u, u_start, unused);
  SoftLabels u_cpu = u_start, u_gpu = u_start;
  LabelDual p_cpu, p_gpu;  // empty
  makeCpuLabelOptimizer()->optimize(problem, u_cpu, p_cpu, 40, 0.0);
  makeCudaLabelOptimizer()->optimize(problem, u_gpu, p_gpu, 40, 0.0);
  ASSERT_EQ(p_gpu.p.size(), std::size_t(37 * 23 * 5 * 2));
  EXPECT_LT(maxAbsDifference(u_gpu.data, u_cpu.data), kLabelTolerance);
  EXPECT_LT(maxAbsDifference(p_gpu.p, p_cpu.p), kLabelTolerance);
}

TEST(CudaLabelStep, RejectsInconsistentInput) {
  SKIP_WITHOUT_GPU();
  auto optimizer = makeCudaLabelOptimizer();
  LabelProblem problem = makeProblem(37, 23, 5, Regularizer::Quadratic, 1u);
  SoftLabels u(36, 23, 5, 0.2f);
  LabelDual p;
  EXPECT_THROW(optimizer->optimize(problem, u, p, 10, 0.0), InputError);
  u = SoftLabels(37, 23, 5, 0.2f);
  problem.data_cost.pop_back();
  EXPECT_THROW(optimizer->optimize(problem, u, p, 10, 0.0), InputError);
  problem = makeProblem(37, 23, 5, Regularizer::Quadratic, 1u);
  problem.weight_y = ImageF(37, 22, 1, 0.5f);
  EXPECT_THROW(optimizer->optimize(problem, u, p, 10, 0.0), InputError);
  problem = makeProblem(37, 23, 5, Regularizer::Quadratic, 1u);
  problem.outlier_only = ImageU8();
  EXPECT_THROW(optimizer->optimize(problem, u, p, 10, 0.0), InputError);
  // A good call after the rejected ones still works.
  problem = makeProblem(37, 23, 5, Regularizer::Quadratic, 1u);
  EXPECT_NO_THROW(optimizer->optimize(problem, u, p, 10, 0.0));
  expectOnSimplex(u);
}

// Backend selection runs on every machine: Auto must pick CUDA exactly when the backend is usable.
TEST(CudaBackendSelection, AutoPicksCudaWhenAvailable) {
  std::string why;
  const bool available = cudaBackendAvailable(&why);
  EXPECT_FALSE(why.empty()) << "cudaBackendAvailable must explain its answer";
  std::string note;
  const Backend chosen = resolveBackend(Backend::Auto, &note);
  if (available) {
    EXPECT_EQ(chosen, Backend::Cuda) << note;
    EXPECT_EQ(resolveBackend(Backend::Cuda), Backend::Cuda);
    EXPECT_EQ(makeCudaLabelOptimizer()->name(), "cuda");
  } else {
    EXPECT_EQ(chosen, Backend::Cpu) << note;
    EXPECT_NE(note.find(why), std::string::npos) << "note '" << note << "' should carry the reason '" << why << "'";
    EXPECT_THROW(makeCudaLabelOptimizer(), BackendError);
    EXPECT_THROW(resolveBackend(Backend::Cuda), BackendError);
  }
  EXPECT_EQ(resolveBackend(Backend::Cpu), Backend::Cpu);
}

}  // namespace
}  // namespace mc_flow
