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
#include <sstream>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/testing/synthetic_scene.h"

using namespace mc_flow;

namespace {

struct Options {
  std::vector<std::pair<int, int>> sizes{{320, 240}, {640, 480}};
  std::vector<int> labels{20, 4};
  int iterations = 150, repeat = 7, warmup = 2, variant = 0;
  std::string backends = "both", regularizers = "both";
};

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream stream(text);
  std::string part;
  while (std::getline(stream, part, separator))
    if (!part.empty()) parts.push_back(part);
  return parts;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

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

int usage(const char* argv0) {
  std::fprintf(stderr,
               "usage: %s [--sizes WxH,...] [--labels N,...] [--iterations 150] [--repeat 7] [--warmup 2]\n"
               "          [--backend both|cpu|cuda] [--regularizer both|quad|tv] [--variant 0]\n",
               argv0);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      auto next = [&]() -> std::string {
        if (i + 1 >= argc) throw ConfigError("missing value after " + a);
        return argv[++i];
      };
      if (a == "--sizes") {
        opt.sizes.clear();
        for (const std::string& s : split(next(), ',')) {
          const auto x = s.find('x');
          if (x == std::string::npos) throw ConfigError("--sizes expects WxH, got '" + s + "'");
          opt.sizes.emplace_back(std::stoi(s.substr(0, x)), std::stoi(s.substr(x + 1)));
        }
      } else if (a == "--labels") {
        opt.labels.clear();
        for (const std::string& s : split(next(), ',')) opt.labels.push_back(std::stoi(s));
      } else if (a == "--iterations") opt.iterations = std::stoi(next());
      else if (a == "--repeat") opt.repeat = std::max(1, std::stoi(next()));
      else if (a == "--warmup") opt.warmup = std::max(0, std::stoi(next()));
      else if (a == "--variant") opt.variant = std::stoi(next());
      else if (a == "--backend") opt.backends = next();
      else if (a == "--regularizer") opt.regularizers = next();
      else if (a == "--help" || a == "-h") return usage(argv[0]), 0;
      else {
        std::fprintf(stderr, "unknown argument '%s'\n", a.c_str());
        return usage(argv[0]);
      }
    }
    if (opt.backends != "both" && opt.backends != "cpu" && opt.backends != "cuda")
      throw ConfigError("--backend must be both, cpu or cuda, got '" + opt.backends + "'");
    std::vector<Regularizer> regularizers;
    if (opt.regularizers == "both") regularizers = {Regularizer::Quadratic, Regularizer::TotalVariation};
    else regularizers = {parseRegularizer(opt.regularizers)};
    for (int n : opt.labels)
      if (n < 2 || n > 128) throw ConfigError("--labels: " + std::to_string(n) + " is outside [2, 128]");

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
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench_labels: %s\n", e.what());
    return 1;
  }
  return 0;
}
