// Label-step benchmark: CPU (OpenMP) against CUDA on realistic problems built from the project's
// synthetic scenes (data costs of eq. 5 for the ground-truth motions and perturbed copies of them,
// 3D-distance weights), at the sizes, label counts and regularisers given. Core only: runs on the GPU machine.
//
//   mcflow_bench_labels [--sizes 320x240,640x480] [--labels 20,4] [--iterations 150] [--repeat 7]
//                       [--warmup 2] [--backend both|cpu|cuda] [--regularizer both|quad|tv] [--variant 0]
//
// Times are wall-clock medians of `repeat` calls after `warmup` calls; optimize() returns only after its
// results are back on the host, so a call's time includes uploads, kernels and downloads. A GPU call with
// 0 iterations measures that fixed per-call cost; (call - fixed) / iterations is the kernel time per iteration.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/eval/synthetic_scene.h"

using namespace mc_flow;

namespace {

// `count` labels: count - 1 motions (the scene's ground-truth twists first, then perturbed copies of them) and
// the outlier label, as the solver would see them after a few outer iterations.
LabelProblem buildProblem(int width, int height, int count, Regularizer regularizer, int variant) {
  SyntheticSceneOptions scene;
  scene.width = width;
  scene.height = height;
  scene.variant = variant;
  const SyntheticPair pair = renderSyntheticPair(scene);
  Config config;
  config.regularizer = regularizer;
  const Pyramid pyramid1 = buildPyramid(pair.frame1, pair.intrinsics, 1, config);
  const Pyramid pyramid2 = buildPyramid(pair.frame2, pair.intrinsics, 1, config);

  std::vector<Vector6d> twists;
  std::mt19937 rng(17);
  std::normal_distribution<double> noise(0.0, 0.01);  // [rad] and [m]
  for (int i = 0; twists.size() + 1 < std::size_t(count); ++i) {
    Vector6d twist = pair.parts.empty() ? Vector6d::Zero() : pair.parts[std::size_t(i) % pair.parts.size()].twist;
    if (i >= int(pair.parts.size()))
      for (int k = 0; k < 6; ++k) twist[k] += noise(rng);
    twists.push_back(twist);
  }
  LabelProblem problem;
  computeDataCosts(pyramid1[0], pyramid2[0], twists, nullptr, config, problem);
  geometricWeights(pyramid1[0], config.min_geometric_weight, problem.weight_x, problem.weight_y);
  return problem;
}

struct Timing {
  double call_ms = 0;
  LabelStats stats;
  SoftLabels u;
};

Timing timeOptimizer(LabelOptimizer& optimizer, const LabelProblem& problem, int iterations, int warmup, int repeat) {
  const SoftLabels u_start(problem.width, problem.height, problem.count, 1.f / float(problem.count));
  Timing timing;
  std::vector<double> times;
  for (int run = 0; run < warmup + repeat; ++run) {
    SoftLabels u = u_start;
    LabelDual p;
    p.reset(problem.width, problem.height, problem.count);
    const auto start = std::chrono::steady_clock::now();
    timing.stats = optimizer.optimize(problem, u, p, iterations, 0.0);
    const auto stop = std::chrono::steady_clock::now();
    if (run >= warmup) times.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
    timing.u = std::move(u);
  }
  timing.call_ms = median(times);
  return timing;
}

}  // namespace

int main(int argc, char** argv) {
  CommandLine cli("mcflow_bench_labels", {{"sizes", true, "WxH,... (default 320x240,640x480)"},
                                          {"labels", true, "label counts N,... in [2, 128] (default 20,4)"},
                                          {"iterations", true, "primal-dual iterations per call (default 150)"},
                                          {"repeat", true, "timed calls; times are the median (default 7)"},
                                          {"warmup", true, "untimed calls first (default 2)"},
                                          {"backend", true, "both | cpu | cuda (default both)"},
                                          {"regularizer", true, "both | quad | tv (default both)"},
                                          {"variant", true, "synthetic scene variant (default 0)"}});
  try {
    cli.parse(argc, argv);
  } catch (const CommandLineError& e) {
    std::fprintf(stderr, "mcflow_bench_labels: %s\n%s", e.what(), cli.usage().c_str());
    return 2;
  }
  if (cli.helpRequested()) {
    std::printf("%s", cli.usage().c_str());
    return 0;
  }
  try {
    struct {
      std::vector<std::pair<int, int>> sizes;
      std::vector<int> labels;
      int iterations, repeat, warmup, variant;
      std::string backends;
    } opt;
    for (const std::string& s : cli.list("sizes", "320x240,640x480")) {
      const auto x = s.find('x');
      if (x == std::string::npos) throw CommandLineError("--sizes expects WxH, got '" + s + "'");
      opt.sizes.emplace_back(std::stoi(s.substr(0, x)), std::stoi(s.substr(x + 1)));
    }
    for (const std::string& s : cli.list("labels", "20,4")) opt.labels.push_back(std::stoi(s));
    opt.iterations = cli.integer("iterations", 150, 0, 1000000);
    opt.repeat = cli.integer("repeat", 7, 1, 10000);
    opt.warmup = cli.integer("warmup", 2, 0, 10000);
    opt.variant = cli.integer("variant", 0, 0, syntheticVariantCount() - 1);
    opt.backends = cli.text("backend", "both");
    if (opt.backends != "both" && opt.backends != "cpu" && opt.backends != "cuda")
      throw CommandLineError("--backend must be both, cpu or cuda, got '" + opt.backends + "'");
    const std::vector<Regularizer> regularizers = regularizerChoice(cli.text("regularizer", "both"));
    for (int n : opt.labels)
      if (n < 2 || n > 128) throw CommandLineError("--labels: " + std::to_string(n) + " is outside [2, 128]");

    const bool run_cpu = opt.backends != "cuda";
    std::string why;
    const bool run_gpu = opt.backends != "cpu" && cudaBackendAvailable(&why);
    if (opt.backends != "cpu" && !run_gpu) std::printf("# CUDA unavailable: %s\n", why.c_str());
    if (run_gpu) std::printf("# %s\n", why.c_str());
    std::printf("# CPU: %d OpenMP threads; %d iterations, tolerance 0, median of %d calls after %d warm-up calls\n",
                omp_get_max_threads(), opt.iterations, opt.repeat, opt.warmup);
    std::printf("%-9s %6s %-5s | %10s %10s | %10s %10s %10s %10s | %8s %10s\n", "size", "labels", "reg", "cpu_ms",
                "cpu_ms/it", "gpu_ms", "gpu_ms/it", "gpu_fix_ms", "kern_ms/it", "speedup", "max|du|");

    auto cpu = makeCpuLabelOptimizer();
    std::unique_ptr<LabelOptimizer> gpu;
    if (run_gpu) gpu = makeCudaLabelOptimizer();
    for (const auto& [width, height] : opt.sizes) {
      for (int n : opt.labels) {
        for (Regularizer regularizer : regularizers) {
          const LabelProblem problem = buildProblem(width, height, n, regularizer, opt.variant);
          Timing cpu_timing, gpu_timing, gpu_fixed;
          if (run_cpu) cpu_timing = timeOptimizer(*cpu, problem, opt.iterations, opt.warmup, opt.repeat);
          if (run_gpu) {
            gpu_timing = timeOptimizer(*gpu, problem, opt.iterations, opt.warmup, opt.repeat);
            gpu_fixed = timeOptimizer(*gpu, problem, 0, opt.warmup, opt.repeat);
          }
          double max_difference = NAN;
          if (run_cpu && run_gpu) {
            max_difference = 0;
            for (std::size_t i = 0; i < cpu_timing.u.data.size(); ++i)
              max_difference = std::max(max_difference, double(std::fabs(cpu_timing.u.data[i] - gpu_timing.u.data[i])));
          }
          const double its = std::max(1, opt.iterations);
          char size_text[32];
          std::snprintf(size_text, sizeof(size_text), "%dx%d", width, height);
          std::printf("%-9s %6d %-5s | %10.2f %10.4f | %10.2f %10.4f %10.2f %10.4f | %8.1f %10.2g\n", size_text, n,
                      regularizer == Regularizer::Quadratic ? "quad" : "tv", cpu_timing.call_ms,
                      cpu_timing.call_ms / its, gpu_timing.call_ms, gpu_timing.call_ms / its, gpu_fixed.call_ms,
                      (gpu_timing.call_ms - gpu_fixed.call_ms) / its,
                      run_cpu && run_gpu ? cpu_timing.call_ms / gpu_timing.call_ms : NAN, max_difference);
          std::fflush(stdout);
        }
      }
    }
  } catch (const CommandLineError& e) {
    std::fprintf(stderr, "mcflow_bench_labels: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench_labels: %s\n", e.what());
    return 1;
  }
  return 0;
}
