// Accuracy and speed benchmark on the project's synthetic scenes (core only: runs wherever the core builds,
// the GPU machine included). Prints one row per (scene, regulariser) and the per-stage timings: wall-clock
// (total_ms and the stages), the process CPU time of a solve (cpu_ms, all threads together) and, on the GPU, the
// kernel launches per solve (a CUB call counts as one); at the end the device memory in use.
//
//   mcflow_bench [--width 320] [--height 240] [--backend auto|cpu|cuda] [--repeat 3] [--noise]
//                [--regularizer both|quad|tv] [--set name=value ...] [--camera-only]
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

namespace {

// Issue 7's camera-only scenes: every variant's room, boxes and arm static, the camera moving by each of a few
// motions per frame up to 10 cm and 8 degrees, with sensor-like noise. A static scene is one rigid motion: the
// default solve should give one segment and the EPE of a solve with a single motion label.
int cameraOnlyBench(const Config& base, int width, int height) {
  struct CameraMotion {
    const char* name;
    Eigen::Vector3d translation_m, rotation_deg;
  };
  const CameraMotion motions[] = {
      {"2cm_1deg", {0.015, -0.005, 0.012}, {0.6, -0.7, 0.3}},
      {"5cm_3deg", {-0.03, 0.02, 0.035}, {-1.5, 2.4, 0.8}},
      {"10cm_8deg", {0.06, -0.03, 0.07}, {4.0, -6.5, 2.0}},
  };
  std::printf("# mcflow_bench --camera-only: static scenes %dx%d, intensity noise 0.01, depth noise 1.5 mm at 1 m "
              "(x depth^2), regularizer %s\n",
              width, height, base.regularizer == Regularizer::Quadratic ? "quad" : "tv");
  std::printf("%-8s %-10s %6s %8s %8s %8s %6s %10s %10s  %s\n", "scene", "motion", "segs", "EPE", "EPE_1", "ratio",
              "segs_1", "total_ms", "total_ms_1", "motion labels over the outer iterations (K-means > after each)");
  for (int variant = 0; variant < syntheticVariantCount(); ++variant)
    for (const CameraMotion& m : motions) {
      SyntheticSceneOptions so;
      so.width = width;
      so.height = height;
      so.variant = variant;
      so.intensity_noise = 0.01;
      so.depth_noise = 0.0015;
      so.camera_only = true;
      so.camera_only_translation_m = m.translation_m;
      so.camera_only_rotation_deg = m.rotation_deg;
      const SyntheticPair pair = renderSyntheticPair(so);
      Config one = base;
      one.initial_labels = 1;
      Solver solver(base), single(one);
      const Result r = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
      const Result r1 = single.solve(pair.frame1, pair.frame2, pair.intrinsics);
      const double epe = opticalFlowErrors(r.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion).epe;
      const double epe1 = opticalFlowErrors(r1.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion).epe;
      std::string counts = r.iterations.empty() ? "-" : std::to_string(r.iterations.front().labels_before);
      for (const OuterIterationStats& it : r.iterations) counts += " > " + std::to_string(it.labels_after);
      std::printf("synth-%-2d %-10s %6zu %8.4f %8.4f %8.3f %6zu %10.1f %10.1f  %s\n", variant, m.name, r.segments.size(),
                  epe, epe1, epe / epe1, r1.segments.size(), r.timings.total, r1.timings.total, counts.c_str());
      std::fflush(stdout);
    }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CommandLine cli("mcflow_bench", {{"width", true, "image width (default 320)"},
                                   {"height", true, "image height (default 240)"},
                                   {"backend", true, "auto | cpu | cuda (default auto)"},
                                   {"repeat", true, "solves per scene; times are the median (default 3)"},
                                   {"noise", false, "add intensity and depth noise to the scenes"},
                                   {"regularizer", true, "both | quad | tv (default both)"},
                                   {"camera-only", false,
                                    "static scenes seen by a moving camera (with Kinect-like noise): segments and "
                                    "EPE of the default solve against one motion label (initial_labels=1)"}});
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
    if (cli.has("camera-only")) {
      Config camera_only = base;
      if (regs.size() == 1) camera_only.regularizer = regs.front();  // "both": the default regulariser
      return cameraOnlyBench(camera_only, width, height);
    }

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
