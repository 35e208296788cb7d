// Soak benchmark (core only: builds and runs on the GPU machine). A looping synthetic stream goes through
// SequencePipeline as the nodelet drives it (warm starts, persistent ids, the GPU-fault fallback) for N solves.
// Every K solves it prints the resident set size (VmRSS), on CUDA the device memory in use (cudaMemGetInfo:
// the whole device's, so run it alone on the GPU) and the time per solve; at the end a verdict whether RSS and
// device memory stayed flat after the warm-up (judgeFlatness in mc_flow/testing/soak.h states the rule; after a
// backend fallback the warm-up starts again). Exit status: 0 flat, 1 not flat (or a solve threw), 2 a usage error.
//
// The stream plays `--frames` rendered frames forwards and backwards (0 1 .. F-1 F-2 .. 1 0 1 ..), stamps 1/30 s
// apart, so it never resets and the motion only reverses at the turns. --fault SOLVE[:STAGE] makes the
// first backend fail there, as the nodelet's rostests do (docs/TESTING.md, "GPU faults").
//
//   mcflow_bench_soak [--solves 10000] [--every N/50] [--warmup N/10] [--width 320] [--height 240] [--frames 30]
//                     [--variant 0] [--backend auto|cpu|cuda] [--rss-tolerance-mb 8] [--device-tolerance-mb 4]
//                     [--set name=value ...]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#ifdef MCFLOW_HAVE_CUDA
#include <cuda_runtime.h>
#endif

#include "mc_flow/core/config.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/testing/fault_injection.h"
#include "mc_flow/testing/soak.h"
#include "mc_flow/eval/synthetic_scene.h"

using namespace mc_flow;

namespace {

constexpr double kMiB = 1024.0 * 1024.0;

struct Options {
  int solves = 10000, every = 0, warmup = 0;
  int width = 320, height = 240, frames = 30, variant = 0;
  double rss_tolerance_mb = 8, device_tolerance_mb = 4;
  Config config;
  SolveBackendFactory make_backend;  // --fault; empty: makeSolveBackend
};

// Device memory in use [bytes] on the current device (all processes), -1 where it cannot be read.
double deviceBytesInUse() {
#ifdef MCFLOW_HAVE_CUDA
  std::size_t free = 0, total = 0;
  if (cudaMemGetInfo(&free, &total) != cudaSuccess) {
    cudaGetLastError();
    return -1;
  }
  return double(total - free);
#else
  return -1;
#endif
}

// Frame index of push p: forwards then backwards over `frames` frames.
int pingPong(long p, int frames) {
  const long period = 2L * (frames - 1);
  const long r = p % period;
  return int(r < frames ? r : period - r);
}

void printVerdict(const char* what, const FlatnessVerdict& v, double tolerance_mb) {
  if (!v.judged) {
    std::printf("%-14s no verdict: fewer than two samples after the warm-up\n", what);
    return;
  }
  std::printf(
      "%-14s %s: solves %ld-%ld: baseline %.1f MiB, end %.1f MiB, growth %+.2f MiB (tolerance %.1f MiB); "
      "peak %.1f MiB, trend %+.1f KiB per 1000 solves\n",
      what, v.flat ? "flat" : "NOT FLAT", v.first_solves, v.last_solves, v.baseline / kMiB, v.end / kMiB,
      v.growth / kMiB, tolerance_mb, v.peak / kMiB, v.slope_per_1000 / 1024.0);
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  CommandLine line("mcflow_bench_soak",
                   {{"solves", true, "pairs to solve (default 10000)"},
                    {"every", true, "print a sample every this many solves (default solves/50)"},
                    {"warmup", true, "solves before the baseline sample (default solves/10)"},
                    {"width", true, "image width (default 320)"},
                    {"height", true, "image height (default 240)"},
                    {"frames", true, "rendered frames the stream loops over (>= 2, default 30)"},
                    {"variant", true, "synthetic scene variant (default 0)"},
                    {"backend", true, "auto | cpu | cuda"},
                    {"fault", true, "SOLVE[:STAGE[:hold=MS]]: the first backend fails (or waits) there once"},
                    {"rss-tolerance-mb", true, "largest RSS growth after the warm-up judged flat (default 8)"},
                    {"device-tolerance-mb", true, "largest device-memory growth judged flat (default 4)"}});
  try {
    line.parse(argc, argv);
    if (line.helpRequested()) {
      std::printf("%s", line.usage().c_str());
      return 0;
    }
    opt.solves = line.integer("solves", 10000, 2, 100000000);
    opt.every = line.integer("every", std::max(1, opt.solves / 50), 1, opt.solves);
    opt.warmup = line.integer("warmup", opt.solves / 10, 0, opt.solves);
    if (opt.warmup + opt.every > opt.solves)
      throw CommandLineError("--warmup " + std::to_string(opt.warmup) + " + --every " + std::to_string(opt.every) +
                             " exceeds --solves " + std::to_string(opt.solves) +
                             ": no sample after the warm-up to judge");
    opt.width = line.integer("width", 320, 16, 8192);
    opt.height = line.integer("height", 240, 16, 8192);
    opt.frames = line.integer("frames", 30, 2, 10000);
    opt.variant = line.integer("variant", 0, 0, syntheticVariantCount() - 1);
    opt.rss_tolerance_mb = line.integer("rss-tolerance-mb", 8, 0, 1 << 20);
    opt.device_tolerance_mb = line.integer("device-tolerance-mb", 4, 0, 1 << 20);
    if (line.has("backend")) opt.config.backend = parseBackend(line.text("backend", "auto"));
    if (line.has("fault"))
      opt.make_backend = faultOnFirstBackend(parseBackendFault(line.text("fault", "")), opt.config.cuda_device);
    line.applySettings(opt.config);
    opt.config.validate();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench_soak: %s\n%s", e.what(), line.usage().c_str());
    return 2;
  }

  try {
    std::vector<StreamFrame> frames(opt.frames);
    for (int t = 0; t < opt.frames; ++t) {
      SyntheticSceneOptions so;
      so.width = opt.width;
      so.height = opt.height;
      so.variant = opt.variant;
      so.stream_events = true;
      ImageU8 colour;
      renderSyntheticFrame(so, t, frames[t].frame, colour, frames[t].K);
      frames[t].source = "soak";
    }
    SequencePipeline pipeline(opt.config, 1, 1.0, opt.make_backend);
    const bool on_cuda = pipeline.solver().backendKind() == Backend::Cuda;
    std::printf(
        "soak: %d solves of %dx%d variant %d over %d looping frames, backend %s, sample every %d, "
        "warm-up %d solves\n",
        opt.solves, opt.width, opt.height, opt.variant, opt.frames, pipeline.solver().backendName().c_str(), opt.every,
        opt.warmup);
    std::printf("%8s %9s %10s %8s %9s %8s %8s %5s %5s %8s %7s %9s\n", "solves", "rss_mb", "device_mb", "mean_ms",
                "median_ms", "max_ms", "segments", "warm", "cold", "cold_fb", "failed", "fallbacks");
    std::fflush(stdout);

    std::vector<MemorySample> rss, device;
    std::vector<double> interval_ms, all_ms;
    all_ms.reserve(std::size_t(opt.solves));
    long solves = 0, failed = 0, warm = 0, cold = 0, cold_fallback = 0, segments = 0, solved_in_interval = 0;
    long interval_warm = 0, interval_cold = 0, interval_cold_fallback = 0, interval_failed = 0;
    long last_fallback = -1;  // the solve of the last backend fallback
    for (long push = 0; solves < opt.solves; ++push) {
      StreamFrame frame = frames[std::size_t(pingPong(push, opt.frames))];
      frame.stamp = double(push) / 30.0;
      const auto start = std::chrono::steady_clock::now();
      const SequenceStep step = pipeline.push(std::move(frame));
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      if (step.outcome == SequenceStep::Outcome::Started) continue;  // the first frame: nothing solved
      ++solves;
      interval_ms.push_back(ms);
      all_ms.push_back(ms);
      if (!step.backend_fallback.empty()) {
        std::printf("solve %ld: %s: continuing on the CPU\n", solves, step.problem.c_str());
        last_fallback = solves;
      }
      if (step.outcome == SequenceStep::Outcome::Solved) {
        const StartKind s = step.result->start;
        interval_warm += s == StartKind::Warm;
        interval_cold += s == StartKind::Cold;
        interval_cold_fallback += s == StartKind::ColdFallback;
        segments += long(step.result->segments.size());
        ++solved_in_interval;
      } else {
        ++interval_failed;
      }
      if (solves % opt.every != 0 && solves != opt.solves) continue;
      const double rss_bytes = processStatusBytes("VmRSS");
      const double device_bytes = on_cuda ? deviceBytesInUse() : -1;
      rss.push_back({solves, rss_bytes});
      if (device_bytes >= 0) device.push_back({solves, device_bytes});
      double mean_ms = 0;
      for (double v : interval_ms) mean_ms += v;
      mean_ms /= double(std::max<std::size_t>(1, interval_ms.size()));
      std::printf("%8ld %9.1f %10s %8.1f %9.1f %8.1f %8.1f %5ld %5ld %8ld %7ld %9ld\n", solves, rss_bytes / kMiB,
                  device_bytes >= 0 ? std::to_string(int(device_bytes / kMiB + 0.5)).c_str() : "-", mean_ms,
                  median(interval_ms), *std::max_element(interval_ms.begin(), interval_ms.end()),
                  solved_in_interval ? double(segments) / double(solved_in_interval) : 0.0, interval_warm,
                  interval_cold, interval_cold_fallback, interval_failed, pipeline.backendFallbacks());
      std::fflush(stdout);
      warm += interval_warm;
      cold += interval_cold;
      cold_fallback += interval_cold_fallback;
      failed += interval_failed;
      interval_ms.clear();
      interval_warm = interval_cold = interval_cold_fallback = interval_failed = segments = solved_in_interval = 0;
    }

    std::sort(all_ms.begin(), all_ms.end());
    const auto percentile = [&](double q) {
      return all_ms[std::min(all_ms.size() - 1, std::size_t(q * double(all_ms.size())))];
    };
    std::printf(
        "\nsolves %ld: solved %ld (warm %ld, cold %ld, cold fallback %ld), failed %ld, backend fallbacks %ld, "
        "resets %ld\n",
        solves, solves - failed, warm, cold, cold_fallback, failed, pipeline.backendFallbacks(), pipeline.resets());
    std::printf("time per solve [ms]: median %.1f, p99 %.1f, max %.1f\n", percentile(0.5), percentile(0.99),
                all_ms.back());
    // Another backend holds other buffers: memory before a fallback says nothing about the solves after it.
    const long warmup = last_fallback < 0 ? opt.warmup : last_fallback + opt.warmup;
    std::printf(
        "rule: over the samples from solve %ld on (%s), the median of the last third exceeds the median of "
        "the first third by no more than the tolerance\n",
        warmup, last_fallback < 0 ? "after the warm-up" : "a warm-up after the last backend fallback");
    const FlatnessVerdict rss_verdict = judgeFlatness(rss, warmup, opt.rss_tolerance_mb * kMiB);
    printVerdict("RSS", rss_verdict, opt.rss_tolerance_mb);
    std::printf("%-14s peak RSS of the process (VmHWM) %.1f MiB\n", "", processStatusBytes("VmHWM") / kMiB);
    bool judged = rss_verdict.judged, flat = rss_verdict.flat;
    if (on_cuda) {
      const FlatnessVerdict device_verdict = judgeFlatness(device, warmup, opt.device_tolerance_mb * kMiB);
      printVerdict("device memory", device_verdict, opt.device_tolerance_mb);
      judged = judged && device_verdict.judged;
      flat = flat && device_verdict.flat;
    } else {
      std::printf("%-14s not sampled (backend %s)\n", "device memory", pipeline.solver().backendName().c_str());
    }
    std::printf("verdict: %s\n", !judged ? "none (too few samples after the warm-up)" : flat ? "flat" : "NOT FLAT");
    flat = judged && flat;
    return flat ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench_soak: %s\n", e.what());
    return 1;
  }
}
