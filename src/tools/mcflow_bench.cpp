// Accuracy and speed benchmark on the project's synthetic scenes (core only: runs wherever the core builds,
// the GPU machine included). Prints one row per (scene, regulariser) and the per-stage timings: wall-clock
// (total_ms and the stages), the process CPU time of a solve (cpu_ms, all threads together) and, on the GPU, the
// kernel launches per solve (a CUB call counts as one); at the end the device memory in use.
//
//   mcflow_bench [--width 320] [--height 240] [--backend auto|cpu|cuda] [--repeat 3] [--noise]
//                [--regularizer both|quad|tv] [--set name=value ...] [--camera-only] [--parts [--truth-start]] [--real
//                DIR]
//
// --real DIR: the real pairs as `mcflow export-real` writes them (PFM, no OpenCV needed), one row per pair and size;
// with --table the accuracy table of `mcflow bench-real` instead, computed by the same code
// (mc_flow/eval/real_pairs.h).
// --concurrent N [--devices 0,1]: N solvers (N cameras) in N threads, each solving synth-0 `repeat` times, solver i on
// CUDA device devices[i % count] (Config::cuda_device; without --devices all on cuda_device): pairs per second against
// one solver alone on the first listed device, and whether every solver's result equals that solver's alone, bit for
// bit ("results identical: yes/no"; exit status 1 on "no", 2 for a device that does not exist).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <map>
#include <memory>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/eval/real_pairs.h"
#include "mc_flow/testing/part_motion.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "mc_flow/testing/same_result.h"

using namespace mc_flow;

namespace {

// One synthetic scene at width x height; `noise`: sensor-like intensity and depth noise (std 0.01, 1.5 mm x Z^2 [m]).
SyntheticSceneOptions sceneOptions(int variant, int width, int height, bool noise) {
  SyntheticSceneOptions so;
  so.width = width;
  so.height = height;
  so.variant = variant;
  if (noise) so.addSensorNoise();
  return so;
}

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
  std::printf(
      "# mcflow_bench --camera-only: static scenes %dx%d, intensity noise 0.01, depth noise 1.5 mm at 1 m "
      "(x depth^2), regularizer %s\n",
      width, height, base.regularizer == Regularizer::Quadratic ? "quad" : "tv");
  std::printf(
      "# world_mm / world_deg: the static world's motion (Result::world) against the camera's true one; nees: "
      "its error's squared Mahalanobis length under the world's covariance (6 dof: 95 %% of single values in "
      "[1.24, 14.4]; the mean of 9 in [3.96, 8.47])\n");
  std::printf("%-8s %-10s %6s %8s %8s %8s %6s %10s %10s %9s %9s %8s  %s\n", "scene", "motion", "segs", "EPE", "EPE_1",
              "ratio", "segs_1", "total_ms", "total_ms_1", "world_mm", "world_deg", "nees",
              "motion labels over the outer iterations (K-means > after each)");
  double nees_sum = 0;
  int nees_count = 0;
  for (int variant = 0; variant < syntheticVariantCount(); ++variant)
    for (const CameraMotion& m : motions) {
      SyntheticSceneOptions so = sceneOptions(variant, width, height, true);
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
      const std::string counts = labelCountTrace(r);
      // Every part of a camera-only scene moves by the static world's apparent motion.
      const Vector6d error = r.world.twist - pair.parts.front().twist;
      const double nees = error.dot(r.world.covariance.ldlt().solve(error));
      nees_sum += nees;
      ++nees_count;
      std::printf("synth-%-2d %-10s %6zu %8.4f %8.4f %8.3f %6zu %10.1f %10.1f %9.3f %9.4f %8.2f  %s\n", variant, m.name,
                  r.segments.size(), epe, epe1, epe / epe1, r1.segments.size(), r.timings.total, r1.timings.total,
                  1000.0 * error.head<3>().norm(), error.tail<3>().norm() * 180.0 / M_PI, nees, counts.c_str());
      std::fflush(stdout);
    }
  std::printf("# mean nees over %d scenes: %.2f\n", nees_count, nees_sum / std::max(1, nees_count));
  return 0;
}

// Issue 7's articulated-object target, per rigid part of every synthetic scene: the segment that covers most of the
// part, that segment's rotation error against the part's true motion and the part's flow error; per scene whether the
// arm's two links (which move differently: an elbow rotation on top of the upper arm's motion) got a segment each.
// `truth_start`: each solve starts from the true parts instead of K-means: a warm start from truthSegmentation with a
// cold solve's outer iterations, pyramid levels and label iterations, and no splits (these warm_* settings override any
// --set). It stays a warm solve otherwise: every motion starts from zero (no dominant-motion start), each level's
// motion step runs motion_iterations_refine iterations, and warm_switch_cost holds the pixels in their true parts. How
// well the motions come out when the segments are right, i.e. what the label count alone cannot improve.
int partsBench(const Config& base, const std::vector<Regularizer>& regs, int width, int height, bool noise,
               bool truth_start) {
  std::printf(
      "# mcflow_bench --parts%s: synthetic scenes %dx%d, noise %s; per rigid part the segment covering most of "
      "its pixels and that segment's errors%s\n",
      truth_start ? " --truth-start" : "", width, height, noise ? "on" : "off",
      truth_start ? " (solves start from the true parts, motions unknown)" : "");
  std::printf(
      "# rot_err: rotation error [deg]; along / across: its parts about the part's longest axis and across it; "
      "fit_err: that of the best rigid motion for the part's true scene flow\n");
  std::printf("%-8s %-5s %-11s %7s %4s %6s %8s %8s %8s %8s %8s %8s\n", "scene", "reg", "part", "pixels", "seg", "cover",
              "rot_deg", "rot_err", "along", "across", "fit_err", "EPE");
  for (int variant = 0; variant < syntheticVariantCount(); ++variant) {
    const SyntheticPair pair = renderSyntheticPair(sceneOptions(variant, width, height, noise));
    for (Regularizer reg : regs) {
      Config config = base;
      config.regularizer = reg;
      if (truth_start) {
        config.warm_start = true;
        config.max_splits_per_iteration = 0;
        config.warm_outer_iterations = config.outer_iterations;
        // The setting's maximum: the whole pyramid wherever it has at most 6 levels above the processing level (320x240
        // has 4 at the default coarsest_min_width of 20 px, 640x480 has 5).
        config.warm_motion_coarse_levels = 6;
        config.warm_label_iterations = config.label_iterations;
        config.warm_label_iterations_final = config.label_iterations_final;
      }
      Solver solver(config);
      const Result r = truth_start ? solver.solve(pair.frame1, pair.frame2, pair.intrinsics, truthSegmentation(pair))
                                   : solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
      if (truth_start && r.start != StartKind::Warm)
        throw std::runtime_error("--truth-start: the solve started " + toString(r.start) +
                                 ", not from the true parts: " + r.start_note);
      const std::vector<PartMotionError> parts = partMotionErrors(r, pair);
      const std::string counts = labelCountTrace(r);
      for (const PartMotionError& e : parts)
        std::printf("synth-%-2d %-5s %-11s %7d %4d %6.3f %8.2f %8.2f %8.2f %8.2f %8.2f %8.3f\n", variant,
                    reg == Regularizer::Quadratic ? "quad" : "tv", e.name.c_str(), e.pixels, e.segment,
                    e.covered_fraction, e.true_rotation_deg, e.rotation_error_deg, e.rotation_error_along_deg,
                    e.rotation_error_across_deg, e.rigid_fit_error_deg, e.flow_epe_px);
      std::printf("# synth-%d %s: %zu segments, arm links apart: %s; motion labels over the outer iterations: %s\n",
                  variant, reg == Regularizer::Quadratic ? "quad" : "tv", r.segments.size(),
                  armLinksApart(parts) ? "yes" : "no", counts.c_str());
      std::fflush(stdout);
    }
  }
  return 0;
}

// Median wall time per stage over `repeat` solves of one pair, and the kernel launches.
struct StageMedians {
  double total = 0, cpu = 0, pyr = 0, init = 0, motion = 0, labels = 0, adapt = 0, occl = 0, output = 0, launches = 0,
         waits = 0;
  // The one-motion merge test (a part of adapt): its time, and its rounds and refitted pairs over the outer iterations.
  double merge = 0, merge_rounds = 0, merge_pairs = 0;
  // The motion step's split (outer iterations): time in the accumulator, in the host's step control and solves,
  // and the IRLS iterations (each one accumulation and, on a GPU, one host round trip).
  double motion_accumulate = 0, motion_solve = 0, irls = 0;
};

StageMedians solveRepeatedly(Solver& solver, const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K,
                             int repeat, Result& r) {
  std::vector<double> total, cpu, pyr, init, motion, labels, adapt, occl, output, launches, waits, accumulate, solve,
      irls, merge, merge_rounds, merge_pairs;
  for (int rep = 0; rep < repeat; ++rep) {
    const std::clock_t cpu_start = std::clock();
    const CudaCounters before = cudaCounters();
    solver.recycle(std::move(r));  // as a stream does: the previous result's image memory is reused
    r = solver.solve(frame1, frame2, K);
    cpu.push_back(1000.0 * double(std::clock() - cpu_start) / CLOCKS_PER_SEC);
    launches.push_back(double(cudaCounters().kernel_launches - before.kernel_launches));
    waits.push_back(double(cudaCounters().host_waits - before.host_waits));
    total.push_back(r.timings.total);
    pyr.push_back(r.timings.preprocessing);
    init.push_back(r.timings.initialisation);
    motion.push_back(r.timings.motion);
    labels.push_back(r.timings.labels);
    adapt.push_back(r.timings.adaptation);
    occl.push_back(r.timings.occlusion);
    output.push_back(r.timings.outputs);
    merge.push_back(r.timings.merge_test);
    double acc = 0, sol = 0, its = 0, rounds = 0, pairs = 0;
    for (const OuterIterationStats& it : r.iterations) {
      rounds += it.merge_rounds;
      pairs += it.merge_pairs_tested;
    }
    merge_rounds.push_back(rounds);
    merge_pairs.push_back(pairs);
    for (const OuterIterationStats& it : r.iterations)
      for (const MotionLevelStats& level : it.motion_levels) {
        acc += level.accumulate_ms;
        sol += level.solve_ms;
        its += level.iterations;
      }
    accumulate.push_back(acc);
    solve.push_back(sol);
    irls.push_back(its);
  }
  StageMedians m;
  m.total = median(total);
  m.cpu = median(cpu);
  m.pyr = median(pyr);
  m.init = median(init);
  m.motion = median(motion);
  m.labels = median(labels);
  m.adapt = median(adapt);
  m.occl = median(occl);
  m.output = median(output);
  m.launches = median(launches);
  m.waits = median(waits);
  m.motion_accumulate = median(accumulate);
  m.motion_solve = median(solve);
  m.irls = median(irls);
  m.merge = median(merge);
  m.merge_rounds = median(merge_rounds);
  m.merge_pairs = median(merge_pairs);
  return m;
}

// The folders <pair>_<W>x<H> of PFM frames and intrinsics.txt (mcflow export-real) in `dir` whose name contains
// `match`, sorted.
std::vector<std::filesystem::path> realPairFolders(const std::string& dir, const std::string& match) {
  std::vector<std::filesystem::path> folders;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    if (entry.is_directory() && std::filesystem::exists(entry.path() / "intrinsics.txt") &&
        entry.path().filename().string().find(match) != std::string::npos)
      folders.push_back(entry.path());
  if (folders.empty())
    throw InputError("--real " + dir + ": no folder with intrinsics.txt (write them with mcflow export-real)");
  std::sort(folders.begin(), folders.end());
  return folders;
}

// The real pairs on any machine, timed: one row per folder with one regulariser, each solve's own occlusions
// excluded from its residuals.
int realBench(const std::string& dir, const std::string& match, const Config& base, int repeat) {
  const std::vector<std::filesystem::path> folders = realPairFolders(dir, match);
  std::printf(
      "# mcflow_bench --real %s: regularizer %s, repeat %d (median times); residuals: RMSE after warping frame 2 "
      "back, occluded pixels excluded\n",
      dir.c_str(), base.regularizer == Regularizer::Quadratic ? "quad" : "tv", repeat);
  std::printf("%-28s %6s %7s %7s | %8s %8s %8s %8s %8s %8s %8s %6s %8s %8s %8s %6s %7s %7s %5s %5s %5s\n", "pair",
              "segs", "rmseI", "rmseZ_mm", "total_ms", "cpu_ms", "pyr", "init", "motion", "labels", "adapt", "merge",
              "occl", "output", "launches", "waits", "m_acc", "m_lm", "irls", "mrnd", "mprs");
  std::printf("# merge: the one-motion merge test's time (a part of adapt), mrnd / mprs its rounds / refitted pairs\n");
  std::printf("# last column: motion labels over the outer iterations, K-means > after each (merged, split)\n");
  std::map<std::string, std::vector<double>> totals_by_size;
  for (const std::filesystem::path& folder : folders) {
    const RealPair pair = readRealPairFolder(folder.string());
    const RgbdFrame &frame1 = pair.frame1, &frame2 = pair.frame2;
    const Intrinsics& K = pair.intrinsics;
    Solver solver(base);
    Result r;
    const StageMedians m = solveRepeatedly(solver, frame1, frame2, K, repeat, r);
    const ResidualRmse rr = warpResidualRmse(frame1, frame2, K, &r.scene_flow, &r.occlusion);
    const std::string counts = labelCountTrace(r, true);
    std::printf(
        "%-28s %6zu %7.4f %7.2f | %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.2f %6.2f %8.1f %8.1f %8.0f %6.0f %7.2f %7.2f "
        "%5.0f %5.0f %5.0f  %s\n",
        folder.filename().string().c_str(), r.segments.size(), rr.photometric, 1000.0 * rr.geometric, m.total, m.cpu,
        m.pyr, m.init, m.motion, m.labels, m.adapt, m.merge, m.occl, m.output, m.launches, m.waits, m.motion_accumulate,
        m.motion_solve, m.irls, m.merge_rounds, m.merge_pairs, counts.c_str());
    std::fflush(stdout);
    totals_by_size[std::to_string(frame1.width()) + "x" + std::to_string(frame1.height())].push_back(m.total);
  }
  for (const auto& [size, totals] : totals_by_size)
    std::printf("# %s: median total over %zu pairs %.1f ms\n", size.c_str(), totals.size(), median(totals));
  return 0;
}

// The real pairs on any machine, scored as `mcflow bench-real` scores them (the same code: zero flow, one label,
// MC-TV and MC-Quad on one pixel set; the table of docs/ACCURACY.md), from the folders of mcflow export-real.
int realTable(const std::string& dir, const std::string& match, const Config& config, int repeat) {
  std::map<std::string, std::string> folder_of;  // pair name -> folder
  std::vector<std::string> names;
  for (const std::filesystem::path& folder : realPairFolders(dir, match)) {
    const std::string name = readRealPairFolder(folder.string()).name;
    if (folder_of.count(name))
      throw InputError("--real " + dir + ": pair '" + name + "' is there at two sizes (choose one with --match, e.g. " +
                       "--match 320x240)");
    folder_of[name] = folder.string();
    names.push_back(name);
  }
  std::string backend;
  const std::vector<PairScores> scores = benchRealPairs(
      names, [&](const std::string& name) { return readRealPairFolder(folder_of.at(name)); }, config, repeat,
      ExclusionMask::UnionOfAll,
      [](const std::string& message) { std::fprintf(stderr, "mcflow_bench: %s\n", message.c_str()); }, &backend);
  std::printf(
      "# mcflow_bench --real %s --table: processing level %d, backend %s, %d run(s) per solve (median times), "
      "excluded: occlusions of all solves\n",
      dir.c_str(), config.processing_level, backend.c_str(), repeat);
  std::fputs(realBenchTable(scores).c_str(), stdout);
  return 0;
}

// "0,1" -> {0, 1}; CommandLineError for anything but non-negative integers.
std::vector<int> parseDevices(const CommandLine& cli, int fallback) {
  std::vector<int> devices;
  for (const std::string& item : cli.list("devices", std::to_string(fallback))) {
    char* end = nullptr;
    const long d = std::strtol(item.c_str(), &end, 10);
    if (end == item.c_str() || *end != '\0' || d < 0 || d > 63)
      throw CommandLineError("--devices '" + cli.text("devices", "") + "': '" + item +
                             "' is not a CUDA device index (0..63, as in Config::cuda_device)");
    devices.push_back(int(d));
  }
  if (devices.empty()) throw CommandLineError("--devices: no device given (e.g. --devices 0,1)");
  return devices;
}

std::string joined(const std::vector<int>& values, const char* separator) {
  std::string text;
  for (std::size_t k = 0; k < values.size(); ++k) text += (k ? separator : "") + std::to_string(values[k]);
  return text;
}

int concurrentBench(const Config& base, int width, int height, int solvers, int repeat,
                    const std::vector<int>& devices) {
  if (base.backend == Backend::Cuda)
    for (int device : devices) {
      std::string why;
      if (!cudaBackendAvailable(&why, device)) {
        std::fprintf(stderr, "mcflow_bench: CUDA backend requested but unavailable: %s\n", why.c_str());
        return 2;
      }
    }
  SyntheticSceneOptions so;
  so.width = width;
  so.height = height;
  const SyntheticPair pair = renderSyntheticPair(so);
  auto configFor = [&](int i) {
    Config config = base;
    config.cuda_device = devices[std::size_t(i) % devices.size()];
    return config;
  };
  // Each solver's last result of the timed run: compared with the one solver's.
  std::vector<Result> last;
  auto run = [&](int count) {
    std::vector<std::unique_ptr<Solver>> each;
    for (int i = 0; i < count; ++i) {
      each.push_back(std::make_unique<Solver>(configFor(i)));
      each.back()->solve(pair.frame1, pair.frame2, pair.intrinsics);  // warm-up: buffers of this size
    }
    last.assign(std::size_t(count), Result());
    std::vector<std::string> errors(static_cast<std::size_t>(count));
    const auto start = std::chrono::steady_clock::now();
    std::vector<std::thread> threads;
    for (int i = 0; i < count; ++i)
      threads.emplace_back([&, i] {
        try {
          for (int k = 0; k < repeat; ++k)
            last[std::size_t(i)] = each[std::size_t(i)]->solve(pair.frame1, pair.frame2, pair.intrinsics);
        } catch (const std::exception& e) {
          errors[std::size_t(i)] = e.what();
        }
      });
    for (std::thread& t : threads) t.join();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    for (const std::string& e : errors)
      if (!e.empty()) throw std::runtime_error("a concurrent solve failed: " + e);
    return double(count * repeat) / seconds;
  };
  const double alone = run(1);
  const Result reference = std::move(last.front());  // the first listed device alone
  const double together = run(solvers);
  std::vector<int> placement;
  for (int i = 0; i < solvers; ++i) placement.push_back(configFor(i).cuda_device);
  const bool on_gpu = reference.backend_kind == Backend::Cuda;
  std::printf("# mcflow_bench --concurrent %d: synth-0 %dx%d, %d solves per solver, backend %s (%s)\n", solvers, width,
              height, repeat, reference.backend.c_str(), reference.backend_note.c_str());
  if (on_gpu)
    std::printf("# solver i on CUDA device devices[i %% %zu]: %s\n", devices.size(), joined(placement, " ").c_str());
  const std::string where_one = on_gpu ? " on device " + std::to_string(devices.front()) : "";
  const std::string where_all = on_gpu ? " on devices " + joined(devices, ",") : "";
  std::printf(
      "one solver%s: %.1f pairs/s (%.1f ms per pair); %d solvers in %d threads%s: %.1f pairs/s in all, %.1f per "
      "solver (%.2fx the throughput of one)\n",
      where_one.c_str(), alone, 1000.0 / alone, solvers, solvers, where_all.c_str(), together, together / solvers,
      together / alone);
  bool identical = true;
  for (int i = 0; i < solvers; ++i) {
    const std::string difference = firstDifference(last[std::size_t(i)], reference);
    if (difference.empty()) continue;
    identical = false;
    std::printf("# solver %d (device %d): its %s differ from the solve alone%s\n", i, placement[std::size_t(i)],
                difference.c_str(), where_one.c_str());
  }
  std::printf(
      "results identical: %s (each solver's last result against the same pair solved by one solver alone%s: "
      "labels, soft labels, flows, moved depth, occlusion, segments, world twist, byte for byte)\n",
      identical ? "yes" : "no", where_one.c_str());
  return identical ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  CommandLine cli("mcflow_bench",
                  {{"width", true, "image width (default 320)"},
                   {"height", true, "image height (default 240)"},
                   {"backend", true, "auto | cpu | cuda (default auto)"},
                   {"repeat", true, "solves per scene; times are the median (default 3; 1 with --table)"},
                   {"noise", false, "add intensity and depth noise to the scenes"},
                   {"regularizer", true, "both | quad | tv (default both)"},
                   {"camera-only", false,
                    "static scenes seen by a moving camera (with Kinect-like noise): segments and "
                    "EPE of the default solve against one motion label (initial_labels=1)"},
                   {"parts", false,
                    "per rigid part of the synthetic scenes: covering segment, rotation error and "
                    "flow error; whether the arm's two links got a segment each"},
                   {"truth-start", false,
                    "with --parts: every solve starts from the true parts (motions unknown, no "
                    "splits): the motions' errors when the segments are right"},
                   {"concurrent", true,
                    "N solvers in N threads on synth-0: throughput against one, results against "
                    "one's bit for bit"},
                   {"devices", true,
                    "with --concurrent: CUDA devices, comma-separated (e.g. 0,1); solver i runs on the "
                    "(i mod count)-th; sets the backend to cuda (default: cuda_device)"},
                   {"match", true, "with --real: only the folders whose name contains this text"},
                   {"table", false,
                    "with --real: the accuracy table of `mcflow bench-real` (zero flow, one label, "
                    "MC-TV, MC-Quad on one pixel set; the same code) instead of the timed rows"},
                   {"real", true,
                    "DIR of real pairs written by `mcflow export-real` (PFM): time, segments and "
                    "residuals per pair"}});
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
    if (cli.has("truth-start") && !cli.has("parts")) throw CommandLineError("--truth-start needs --parts");
    const std::vector<Regularizer> regs = regularizerChoice(cli.text("regularizer", "both"));
    if (cli.has("devices") && !cli.has("concurrent")) throw CommandLineError("--devices needs --concurrent");
    if (cli.has("concurrent")) {
      if (cli.has("devices")) {
        if (base.backend == Backend::Cpu) throw CommandLineError("--devices needs the cuda backend, not --backend cpu");
        base.backend = Backend::Cuda;  // a GPU per listed device, or the error naming the one that is missing
      }
      return concurrentBench(base, width, height, cli.integer("concurrent", 2, 1, 64), repeat,
                             parseDevices(cli, base.cuda_device));
    }
    if (cli.has("table") && !cli.has("real")) throw CommandLineError("--table needs --real DIR");
    if (cli.has("table")) {
      if (cli.has("regularizer")) throw CommandLineError("--table solves with both regularisers: no --regularizer");
      return realTable(cli.text("real", ""), cli.text("match", ""), base, cli.integer("repeat", 1, 1, 1000));
    }
    if (cli.has("real")) {
      Config real = base;
      if (regs.size() == 1) real.regularizer = regs.front();
      return realBench(cli.text("real", ""), cli.text("match", ""), real, repeat);
    }
    if (cli.has("parts")) return partsBench(base, regs, width, height, noise, cli.has("truth-start"));
    if (cli.has("camera-only")) {
      Config camera_only = base;
      if (regs.size() == 1) camera_only.regularizer = regs.front();  // "both": the default regulariser
      return cameraOnlyBench(camera_only, width, height);
    }

    std::printf("# mcflow_bench: synthetic scenes %dx%d, noise %s, repeat %d (median times)\n", width, height,
                noise ? "on" : "off", repeat);
    std::printf("%-8s %-5s %7s %7s %8s %7s %7s %7s %7s %6s | %8s %8s %8s %8s %8s %8s %8s %8s %8s %8s %6s %7s %7s %5s\n",
                "scene", "reg", "EPE", "AAE", "EPE3D_mm", "seg", "occ", "rmseI", "rmseZ", "labels", "total_ms",
                "cpu_ms", "pyr", "init", "motion", "labels", "adapt", "occl", "output", "launches", "waits", "m_acc",
                "m_lm", "irls");
    for (int variant = 0; variant < syntheticVariantCount(); ++variant) {
      const SyntheticPair pair = renderSyntheticPair(sceneOptions(variant, width, height, noise));
      for (Regularizer reg : regs) {
        Config config = base;
        config.regularizer = reg;
        Solver solver(config);
        Result r;
        const StageMedians m = solveRepeatedly(solver, pair.frame1, pair.frame2, pair.intrinsics, repeat, r);
        const FlowErrors fe = opticalFlowErrors(r.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
        const double epe3d = sceneFlowEpe(r.scene_flow, pair.gt_scene_flow, &pair.gt_occlusion);
        const double seg = segmentationAgreement(r.labels, pair.gt_parts);
        const double occ = maskAgreement(r.occlusion, pair.gt_occlusion, nullptr);
        const ResidualRmse rr =
            warpResidualRmse(pair.frame1, pair.frame2, pair.intrinsics, &r.scene_flow, &r.occlusion);
        std::printf(
            "synth-%-2d %-5s %7.3f %7.3f %8.2f %7.3f %7.3f %7.4f %7.4f %6d | %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.2f "
            "%8.1f %8.1f %8.0f %6.0f %7.2f %7.2f %5.0f\n",
            variant, reg == Regularizer::Quadratic ? "quad" : "tv", fe.epe, fe.aae_deg, epe3d * 1000.0, seg, occ,
            rr.photometric, rr.geometric, int(r.segments.size()), m.total, m.cpu, m.pyr, m.init, m.motion, m.labels,
            m.adapt, m.occl, m.output, m.launches, m.waits, m.motion_accumulate, m.motion_solve, m.irls);
        std::fflush(stdout);
      }
    }
    std::size_t used = 0, device_total = 0;
    if (cudaDeviceMemory(&used, &device_total))
      std::printf(
          "# device memory in use (all processes): %.1f MiB of %.1f MiB; allocations so far: %llu device, %llu "
          "page-locked; label-step graphs instantiated: %llu\n",
          double(used) / (1024.0 * 1024.0), double(device_total) / (1024.0 * 1024.0),
          static_cast<unsigned long long>(cudaCounters().device_allocations),
          static_cast<unsigned long long>(cudaCounters().pinned_allocations),
          static_cast<unsigned long long>(cudaCounters().graph_instantiations));
    return 0;
  } catch (const CommandLineError& e) {
    std::fprintf(stderr, "mcflow_bench: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench: %s\n", e.what());
    return 1;
  }
}
