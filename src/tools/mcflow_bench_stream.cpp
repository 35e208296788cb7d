// Stream-mode benchmark on synthetic sequences (core only: runs on the GPU machine too). Each sequence is
// solved twice with persistent ids: cold (every pair from K-means, ids matched by overlap) and warm (each
// pair from the previous pair's segments and motions). Prints per mode: time per pair, optical-flow EPE,
// id consistency (the fraction of consecutive pairs in which each true part keeps the id most of its
// pixels carry), how many pairs after it starts moving the late box has a segment of its own, and how many
// warm starts fell back to a cold solve.
//
//   mcflow_bench_stream [--frames 30] [--variants 0,1,2] [--width 320] [--height 240] [--backend auto|cpu|cuda]
//                       [--modes cold,warm] [--noise] [--ids] [--set name=value ...]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/testing/metrics.h"
#include "mc_flow/testing/synthetic_scene.h"

using namespace mc_flow;

namespace {

struct Options {
  int frames = 30, width = 320, height = 240;
  std::vector<int> variants{0, 1, 2};
  std::vector<bool> warm_modes{false, true};
  bool noise = false;
  bool print_ids = false;  // per pair, the majority id of each true part (stderr)
  Config config;
};

constexpr int kLatePart = 10;       // synthetic_scene.h: the box that starts moving at frame 10
constexpr int kLateStartPair = 10;  // the first pair in which it moves
constexpr int kMinPartPixels = 200; // parts smaller than this in a pair are not judged

struct ModeStats {
  std::vector<double> ms, epe;
  StageTimings stages;  // summed over the pairs after the first
  long kept = 0, judged = 0;  // id consistency
  int late_delay = -1;        // pairs after kLateStartPair until the late box has its own segment (-1: never)
  int fallbacks = 0, warm = 0;
};

// Majority predicted id of each true part (parts with enough pixels).
std::map<int, int> majorityIds(const ImageI32& labels, const ImageI32& parts) {
  std::map<int, std::map<int, int>> votes;
  std::map<int, int> size;
  for (std::size_t k = 0; k < labels.data.size(); ++k) {
    ++size[parts.data[k]];
    if (labels.data[k] > 0) ++votes[parts.data[k]][labels.data[k]];
  }
  std::map<int, int> out;
  for (const auto& [part, v] : votes) {
    if (size[part] < kMinPartPixels) continue;
    const auto best = std::max_element(v.begin(), v.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
    out[part] = best->first;
  }
  return out;
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / double(v.size());
}

ModeStats runSequence(const std::vector<SyntheticPair>& pairs, const Config& config, bool print_ids) {
  ModeStats st;
  Solver solver(config);
  Result previous;
  std::map<int, int> previous_ids;
  for (std::size_t t = 0; t < pairs.size(); ++t) {
    const SyntheticPair& p = pairs[t];
    const auto start = std::chrono::steady_clock::now();
    Result r = t == 0 ? solver.solve(p.frame1, p.frame2, p.intrinsics)
                      : solver.solve(p.frame1, p.frame2, p.intrinsics, previous);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (t > 0) {  // the first pair is cold in both modes
      st.ms.push_back(ms);
      const StageTimings& s = r.timings;
      st.stages.preprocessing += s.preprocessing;
      st.stages.initialisation += s.initialisation;
      st.stages.motion += s.motion;
      st.stages.labels += s.labels;
      st.stages.adaptation += s.adaptation;
      st.stages.occlusion += s.occlusion;
      st.stages.outputs += s.outputs;
      st.warm += r.start == StartKind::Warm;
      st.fallbacks += r.start == StartKind::ColdFallback;
    }
    st.epe.push_back(opticalFlowErrors(r.optical_flow, p.gt_optical_flow, &p.gt_occlusion).epe);
    const std::map<int, int> ids = majorityIds(r.labels, p.gt_parts);
    if (print_ids) {
      std::fprintf(stderr, "pair %2zu %-13s", t, toString(r.start).c_str());
      for (const auto& [part, id] : ids) std::fprintf(stderr, " %d:%d", part, id);
      std::fprintf(stderr, "  segments");
      for (const Segment& s : r.segments) std::fprintf(stderr, " %d", s.id);
      std::fprintf(stderr, "\n");
    }
    if (t > 0)
      for (const auto& [part, id] : ids)
        if (previous_ids.count(part)) {
          ++st.judged;
          st.kept += previous_ids.at(part) == id;
        }
    if (int(t) >= kLateStartPair && st.late_delay < 0 && ids.count(kLatePart) && ids.count(0) &&
        ids.at(kLatePart) != ids.at(0))
      st.late_delay = int(t) - kLateStartPair;
    previous_ids = ids;
    previous = std::move(r);
  }
  return st;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  CommandLine line("mcflow_bench_stream",
                   {{"frames", true, "frames per sequence (>= 3, default 30)"},
                    {"variants", true, "comma-separated synthetic variants (default 0,1,2)"},
                    {"width", true, "image width (default 320)"},
                    {"height", true, "image height (default 240)"},
                    {"backend", true, "auto | cpu | cuda"},
                    {"modes", true, "comma-separated: cold, warm (default both)"},
                    {"noise", false, "Kinect-like intensity and depth noise"},
                    {"ids", false, "print each pair's majority id per true part on stderr"}});
  try {
    line.parse(argc, argv);
    if (line.helpRequested()) {
      std::printf("%s", line.usage().c_str());
      return 0;
    }
    opt.frames = line.integer("frames", 30, 3, 100000);
    opt.width = line.integer("width", 320, 16, 8192);
    opt.height = line.integer("height", 240, 16, 8192);
    opt.variants.clear();
    for (const std::string& v : line.list("variants", "0,1,2")) opt.variants.push_back(std::stoi(v));
    opt.warm_modes.clear();
    for (const std::string& m : line.list("modes", "cold,warm")) {
      if (m != "cold" && m != "warm") throw ConfigError("--modes: '" + m + "' is neither cold nor warm");
      opt.warm_modes.push_back(m == "warm");
    }
    if (line.has("backend")) opt.config.backend = parseBackend(line.text("backend", "auto"));
    opt.noise = line.has("noise");
    opt.print_ids = line.has("ids");
    line.applySettings(opt.config);
    opt.config.validate();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench_stream: %s\n%s", e.what(), line.usage().c_str());
    return 2;
  }
  std::printf("%-8s %-5s %6s %9s %9s %9s %8s %9s %9s %6s   %s\n", "variant", "mode", "pairs", "mean_ms", "median_ms",
              "mean_epe", "id_keep", "late_pairs", "fallbacks", "warm",
              "mean stage ms: pyramid init motion labels count occl outputs");
  for (const int variant : opt.variants) {
    std::vector<SyntheticPair> pairs;
    for (int t = 0; t + 1 < opt.frames; ++t) {
      SyntheticSceneOptions so;
      so.width = opt.width;
      so.height = opt.height;
      so.variant = variant;
      so.first_frame = t;
      so.stream_events = true;
      if (opt.noise) so.addSensorNoise();
      pairs.push_back(renderSyntheticPair(so));
    }
    for (const bool warm : opt.warm_modes) {
      Config config = opt.config;
      config.warm_start = warm;
      const ModeStats st = runSequence(pairs, config, opt.print_ids);
      const double n = std::max<double>(1.0, double(st.ms.size()));
      const StageTimings& s = st.stages;
      std::printf("%-8d %-5s %6zu %9.1f %9.1f %9.4f %8.3f %9d %9d %6d   %.1f %.1f %.1f %.1f %.1f %.1f %.1f\n", variant,
                  warm ? "warm" : "cold", pairs.size(), mean(st.ms), median(st.ms), mean(st.epe),
                  st.judged ? double(st.kept) / double(st.judged) : 0.0, st.late_delay, st.fallbacks, st.warm,
                  s.preprocessing / n, s.initialisation / n, s.motion / n, s.labels / n, s.adaptation / n,
                  s.occlusion / n, s.outputs / n);
      std::fflush(stdout);
    }
  }
  return 0;
}
