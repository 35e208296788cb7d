// Accuracy and speed benchmark on the project's synthetic scenes (core only: runs wherever the core builds,
// the GPU machine included). Prints one row per (scene, regulariser) and the per-stage timings: wall-clock
// (total_ms and the stages) and the process CPU time of a solve (cpu_ms, all threads together).
//
//   mcflow_bench [--width 320] [--height 240] [--backend auto|cpu|cuda] [--repeat 3] [--noise]
//                [--regularizer both|quad|tv] [--set name=value ...]
#include <algorithm>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/testing/metrics.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/testing/synthetic_scene.h"

using namespace mc_flow;

namespace {

struct Options {
  int width = 320, height = 240, repeat = 3;
  bool noise = false;
  std::string regularizers = "both";
  Config config;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

int usage(const char* argv0) {
  std::fprintf(stderr,
               "usage: %s [--width W] [--height H] [--backend auto|cpu|cuda] [--repeat N] [--noise]\n"
               "          [--regularizer both|quad|tv] [--set name=value ...]\n",
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
      if (a == "--width") opt.width = std::stoi(next());
      else if (a == "--height") opt.height = std::stoi(next());
      else if (a == "--repeat") opt.repeat = std::max(1, std::stoi(next()));
      else if (a == "--backend") opt.config.backend = parseBackend(next());
      else if (a == "--noise") opt.noise = true;
      else if (a == "--regularizer") opt.regularizers = next();
      else if (a == "--set") {
        const std::string kv = next();
        const auto eq = kv.find('=');
        if (eq == std::string::npos) throw ConfigError("--set expects name=value, got '" + kv + "'");
        opt.config.set(kv.substr(0, eq), kv.substr(eq + 1));
      } else if (a == "--help" || a == "-h") return usage(argv[0]), 0;
      else {
        std::fprintf(stderr, "unknown argument '%s'\n", a.c_str());
        return usage(argv[0]);
      }
    }
    std::vector<Regularizer> regs;
    if (opt.regularizers == "both") regs = {Regularizer::Quadratic, Regularizer::TotalVariation};
    else regs = {parseRegularizer(opt.regularizers)};

    std::printf("# mcflow_bench: synthetic scenes %dx%d, noise %s, repeat %d (median times)\n", opt.width, opt.height,
                opt.noise ? "on" : "off", opt.repeat);
    std::printf("%-8s %-5s %7s %7s %8s %7s %7s %7s %7s %6s | %8s %8s %8s %8s %8s %8s %8s %8s\n", "scene", "reg", "EPE", "AAE",
                "EPE3D_mm", "seg", "occ", "rmseI", "rmseZ", "labels", "total_ms", "cpu_ms", "pyr", "init", "motion",
                "labels", "occl", "output");
    for (int variant = 0; variant < syntheticVariantCount(); ++variant) {
      SyntheticSceneOptions so;
      so.width = opt.width;
      so.height = opt.height;
      so.variant = variant;
      if (opt.noise) {
        so.intensity_noise = 0.01;
        so.depth_noise = 0.0015;
      }
      const SyntheticPair pair = renderSyntheticPair(so);
      for (Regularizer reg : regs) {
        Config config = opt.config;
        config.regularizer = reg;
        Solver solver(config);
        std::vector<double> total, cpu, pyr, init, motion, labels, occl, output;
        Result r;
        for (int rep = 0; rep < opt.repeat; ++rep) {
          const std::clock_t cpu_start = std::clock();
          r = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
          cpu.push_back(1000.0 * double(std::clock() - cpu_start) / CLOCKS_PER_SEC);
          total.push_back(r.timings.total);
          pyr.push_back(r.timings.preprocessing);
          init.push_back(r.timings.initialisation);
          motion.push_back(r.timings.motion);
          labels.push_back(r.timings.labels + r.timings.adaptation);
          occl.push_back(r.timings.occlusion);
          output.push_back(r.timings.outputs);
        }
        const FlowErrors fe = opticalFlowErrors(r.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
        const double epe3d = sceneFlowEpe(r.scene_flow, pair.gt_scene_flow, &pair.gt_occlusion);
        const double seg = segmentationAgreement(r.labels, pair.gt_parts);
        const double occ = maskAgreement(r.occlusion, pair.gt_occlusion, nullptr);
        const ResidualRmse rr = warpResidualRmse(pair.frame1, pair.frame2, pair.intrinsics, &r.scene_flow, &r.occlusion);
        std::printf("synth-%-2d %-5s %7.3f %7.3f %8.2f %7.3f %7.3f %7.4f %7.4f %6d | %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f\n",
                    variant, reg == Regularizer::Quadratic ? "quad" : "tv", fe.epe, fe.aae_deg, epe3d * 1000.0, seg, occ,
                    rr.photometric, rr.geometric, int(r.segments.size()), median(total), median(cpu), median(pyr), median(init),
                    median(motion), median(labels), median(occl), median(output));
        std::fflush(stdout);
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench: %s\n", e.what());
    return 1;
  }
}
