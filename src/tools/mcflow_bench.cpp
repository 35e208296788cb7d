// Accuracy and speed benchmark on the project's synthetic scenes (core only: runs wherever the core builds,
// the GPU machine included). Prints one row per (scene, regulariser) and the per-stage timings: wall-clock
// (total_ms and the stages), the process CPU time of a solve (cpu_ms, all threads together) and, on the GPU, the
// kernel launches per solve (a CUB call counts as one); at the end the device memory in use.
//
//   mcflow_bench [--width 320] [--height 240] [--backend auto|cpu|cuda] [--repeat 3] [--noise]
//                [--regularizer both|quad|tv] [--set name=value ...]
#include <cstdio>
#include <ctime>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/testing/metrics.h"
#include "mc_flow/testing/synthetic_scene.h"

using namespace mc_flow;

int main(int argc, char** argv) {
  CommandLine cli("mcflow_bench", {{"width", true, "image width (default 320)"},
                                   {"height", true, "image height (default 240)"},
                                   {"backend", true, "auto | cpu | cuda (default auto)"},
                                   {"repeat", true, "solves per scene; times are the median (default 3)"},
                                   {"noise", false, "add intensity and depth noise to the scenes"},
                                   {"regularizer", true, "both | quad | tv (default both)"}});
  try {
    cli.parse(argc, argv);
  } catch (const CommandLineError& e) {
    std::fprintf(stderr, "mcflow_bench: %s\n%s", e.what(), cli.usage().c_str());
    return 2;
  }
  if (cli.helpRequested()) {
    std::printf("%s", cli.usage().c_str());
    return 0;
  }
  try {
    const int width = cli.integer("width", 320, 16, 8192), height = cli.integer("height", 240, 16, 8192);
    const int repeat = cli.integer("repeat", 3, 1, 1000);
    const bool noise = cli.has("noise");
    Config base;
    base.backend = parseBackend(cli.text("backend", "auto"));
    cli.applySettings(base);
    const std::vector<Regularizer> regs = regularizerChoice(cli.text("regularizer", "both"));

    std::printf("# mcflow_bench: synthetic scenes %dx%d, noise %s, repeat %d (median times)\n", width, height,
                noise ? "on" : "off", repeat);
    std::printf("%-8s %-5s %7s %7s %8s %7s %7s %7s %7s %6s | %8s %8s %8s %8s %8s %8s %8s %8s %8s\n", "scene", "reg", "EPE", "AAE",
                "EPE3D_mm", "seg", "occ", "rmseI", "rmseZ", "labels", "total_ms", "cpu_ms", "pyr", "init", "motion",
                "labels", "occl", "output", "launches");
    for (int variant = 0; variant < syntheticVariantCount(); ++variant) {
      SyntheticSceneOptions so;
      so.width = width;
      so.height = height;
      so.variant = variant;
      if (noise) {
        so.intensity_noise = 0.01;
        so.depth_noise = 0.0015;
      }
      const SyntheticPair pair = renderSyntheticPair(so);
      for (Regularizer reg : regs) {
        Config config = base;
        config.regularizer = reg;
        Solver solver(config);
        std::vector<double> total, cpu, pyr, init, motion, labels, occl, output, launches;
        Result r;
        for (int rep = 0; rep < repeat; ++rep) {
          const std::clock_t cpu_start = std::clock();
          const std::uint64_t launches_before = cudaCounters().kernel_launches;
          r = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
          cpu.push_back(1000.0 * double(std::clock() - cpu_start) / CLOCKS_PER_SEC);
          launches.push_back(double(cudaCounters().kernel_launches - launches_before));
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
        std::printf("synth-%-2d %-5s %7.3f %7.3f %8.2f %7.3f %7.3f %7.4f %7.4f %6d | %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.0f\n",
                    variant, reg == Regularizer::Quadratic ? "quad" : "tv", fe.epe, fe.aae_deg, epe3d * 1000.0, seg, occ,
                    rr.photometric, rr.geometric, int(r.segments.size()), median(total), median(cpu), median(pyr), median(init),
                    median(motion), median(labels), median(occl), median(output), median(launches));
        std::fflush(stdout);
      }
    }
    std::size_t used = 0, device_total = 0;
    if (cudaDeviceMemory(&used, &device_total))
      std::printf("# device memory in use (all processes): %.1f MiB of %.1f MiB; allocations so far: %llu device, %llu "
                  "page-locked\n",
                  double(used) / (1024.0 * 1024.0), double(device_total) / (1024.0 * 1024.0),
                  static_cast<unsigned long long>(cudaCounters().device_allocations),
                  static_cast<unsigned long long>(cudaCounters().pinned_allocations));
    return 0;
  } catch (const CommandLineError& e) {
    std::fprintf(stderr, "mcflow_bench: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench: %s\n", e.what());
    return 1;
  }
}
