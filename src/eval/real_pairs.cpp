#include "mc_flow/eval/real_pairs.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>

#include "mc_flow/core/error.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/sampling.h"
#include "mc_flow/io/flow_io.h"

namespace mc_flow {

namespace {

/// Median of each stage over the repetitions.
StageTimings medianTimings(const std::vector<StageTimings>& runs) {
  auto stage = [&](double StageTimings::*member) {
    std::vector<double> values;
    for (const StageTimings& t : runs) values.push_back(t.*member);
    return median(values);
  };
  StageTimings t;
  for (double StageTimings::*m :
       {&StageTimings::preprocessing, &StageTimings::initialisation, &StageTimings::motion, &StageTimings::labels,
        &StageTimings::adaptation, &StageTimings::occlusion, &StageTimings::outputs, &StageTimings::total})
    t.*m = stage(m);
  return t;
}

Result solveRepeated(const RealPair& pair, const Config& config, int repeat, StageTimings& timings) {
  Solver solver(config);
  std::vector<StageTimings> runs;
  Result result;
  for (int r = 0; r < std::max(1, repeat); ++r) {
    result = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
    runs.push_back(result.timings);
  }
  timings = medianTimings(runs);
  return result;
}

}  // namespace

std::vector<std::string> realPairNames() {
  return {"two_people_walking", "robot", "cleaning_whiteboard", "tum_fr2_desk"};
}

Intrinsics realPairIntrinsics640(const std::string& name) {
  if (name == "tum_fr2_desk") return {520.9, 521.0, 325.1, 249.7};
  for (const std::string& known : realPairNames())
    if (name == known) return {527.4, 532.2, 319.5, 239.5};  // Joint-VO-SF capture: 62.5 x 48.5 deg field of view
  throw InputError("unknown real pair '" + name + "' (no intrinsics known for it)");
}

ImageF cleanDepth(const ImageF& depth, const Config& config) {
  ImageF cleaned = depth;
  for (float& z : cleaned.data)
    if (!(std::isfinite(z) && z >= config.min_depth && z <= config.max_depth)) z = 0.f;
  return cleaned;
}

RgbdFrame halveFrame(const RgbdFrame& frame, const Config& config) {
  RgbdFrame half;
  half.intensity = downsampleIntensity(frame.intensity);
  half.depth = downsampleDepth(cleanDepth(frame.depth, config), config.depth_downsample_range);
  return half;
}

RealPair prepareRealPair(const std::string& name, RgbdFrame frame1, RgbdFrame frame2, const std::string& source,
                         int halvings, const Config& config) {
  if (halvings < 0) throw InputError("prepareRealPair: halvings = " + std::to_string(halvings) + " must be >= 0");
  RealPair pair;
  pair.name = name;
  pair.frame1 = std::move(frame1);
  pair.frame2 = std::move(frame2);
  pair.intrinsics = realPairIntrinsics640(name);
  if (pair.frame1.width() != 640 || pair.frame1.height() != 480)
    throw InputError("real pair '" + name + "': expected 640x480 images, " + source + " is " +
                     std::to_string(pair.frame1.width()) + "x" + std::to_string(pair.frame1.height()));
  if (!pair.frame2.intensity.sameSize(pair.frame1.intensity))
    throw InputError("real pair '" + name + "': the two frames differ in size");
  pair.frame1.depth = cleanDepth(pair.frame1.depth, config);
  pair.frame2.depth = cleanDepth(pair.frame2.depth, config);
  for (int h = 0; h < halvings; ++h) {
    pair.frame1 = halveFrame(pair.frame1, config);
    pair.frame2 = halveFrame(pair.frame2, config);
    pair.intrinsics = pair.intrinsics.scaled(0.5);
  }
  return pair;
}

void writeRealPairFolder(const std::string& dir, const RealPair& pair) {
  std::filesystem::create_directories(dir);
  io::writePfm(dir + "/intensity0.pfm", pair.frame1.intensity);
  io::writePfm(dir + "/depth0.pfm", pair.frame1.depth);
  io::writePfm(dir + "/intensity1.pfm", pair.frame2.intensity);
  io::writePfm(dir + "/depth1.pfm", pair.frame2.depth);
  std::ofstream intrinsics(dir + "/intrinsics.txt");
  intrinsics.precision(17);
  intrinsics << pair.intrinsics.fx << " " << pair.intrinsics.fy << " " << pair.intrinsics.cx << " "
             << pair.intrinsics.cy << "\n";
  if (!intrinsics) throw io::FileError("cannot write " + dir + "/intrinsics.txt");
}

RealPair readRealPairFolder(const std::string& dir) {
  const std::filesystem::path folder(dir);
  RealPair pair;
  auto frame = [&](const char* intensity, const char* depth) {
    RgbdFrame f;
    f.intensity = io::readPfm((folder / intensity).string());
    f.depth = io::readPfm((folder / depth).string());
    return f;
  };
  pair.frame1 = frame("intensity0.pfm", "depth0.pfm");
  pair.frame2 = frame("intensity1.pfm", "depth1.pfm");
  std::ifstream in(folder / "intrinsics.txt");
  if (!(in >> pair.intrinsics.fx >> pair.intrinsics.fy >> pair.intrinsics.cx >> pair.intrinsics.cy))
    throw InputError((folder / "intrinsics.txt").string() + ": expected four numbers fx fy cx cy");
  pair.name = folder.filename().string();
  const std::string size = "_" + std::to_string(pair.frame1.width()) + "x" + std::to_string(pair.frame1.height());
  if (pair.name.size() > size.size() && pair.name.compare(pair.name.size() - size.size(), size.size(), size) == 0)
    pair.name.resize(pair.name.size() - size.size());
  return pair;
}

ImageU8 commonExclusionMask(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K,
                            const std::vector<const ImageF*>& scene_flows,
                            const std::vector<const ImageU8*>& occlusions) {
  const int w = frame1.depth.width, h = frame1.depth.height;
  for (const ImageU8* o : occlusions)
    if (!o || !o->sameSize(w, h))
      throw InputError("commonExclusionMask: an occlusion mask is missing or of another size");
  for (const ImageF* f : scene_flows)
    if (f && (!f->sameSize(w, h) || f->channels != 3))
      throw InputError("commonExclusionMask: a scene flow is not 3 channels of the frame's size");

  ImageU8 excluded(w, h, 1, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t k = std::size_t(y) * w + x;
      bool drop = !isValidDepth(frame1.depth.data[k]);
      for (const ImageU8* o : occlusions) drop = drop || o->data[k] != 0;
      for (const ImageF* f : scene_flows) {
        if (drop) break;
        // Mirror the warp of warpResidualRmse: P2 = P + flow, projected and sampled in frame 2.
        const double z = frame1.depth.data[k];
        double P2[3] = {z * (x - K.cx) / K.fx, z * (y - K.cy) / K.fy, z};
        if (f) {
          const float* v = &f->data[3 * k];
          if (!(std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]))) {
            drop = true;
            break;
          }
          for (int c = 0; c < 3; ++c) P2[c] += v[c];
        }
        if (!(P2[2] > 0)) {
          drop = true;
          break;
        }
        const float u = float(K.fx * P2[0] / P2[2] + K.cx), v = float(K.fy * P2[1] / P2[2] + K.cy);
        float i2 = 0, z2 = 0;
        drop = !sampleBilinear(frame2.intensity, u, v, 0, i2) || !sampleDepthBilinear(frame2.depth, u, v, z2);
      }
      excluded.data[k] = drop ? 255 : 0;
    }
  return excluded;
}

const MethodScore& PairScores::method(const std::string& name) const {
  for (const MethodScore& m : methods)
    if (m.method == name) return m;
  throw InputError("pair '" + pair + "' has no method '" + name + "'");
}

PairSolves solveRealPair(const RealPair& pair, const Config& base, int repeat) {
  PairSolves solves;
  Config one = base;
  one.initial_labels = 1;  // a single rigid motion for the whole image: dense robust visual odometry
  one.max_labels = 1;      // and no split proposals
  solves.one_label = solveRepeated(pair, one, repeat, solves.one_label_time);
  Config tv = base;
  tv.regularizer = Regularizer::TotalVariation;
  solves.tv = solveRepeated(pair, tv, repeat, solves.tv_time);
  Config quad = base;
  quad.regularizer = Regularizer::Quadratic;
  solves.quad = solveRepeated(pair, quad, repeat, solves.quad_time);
  return solves;
}

PairScores scoreRealPair(const RealPair& pair, const PairSolves& solves, ExclusionMask mask) {
  std::vector<const ImageU8*> occlusions = {&solves.tv.occlusion, &solves.quad.occlusion};
  if (mask == ExclusionMask::UnionOfAll) occlusions.push_back(&solves.one_label.occlusion);
  const ImageU8 excluded = commonExclusionMask(
      pair.frame1, pair.frame2, pair.intrinsics,
      {nullptr, &solves.one_label.scene_flow, &solves.tv.scene_flow, &solves.quad.scene_flow}, occlusions);

  PairScores scores;
  scores.pair = pair.name;
  scores.width = pair.frame1.width();
  scores.height = pair.frame1.height();
  auto add = [&](const std::string& name, const Result* result, const StageTimings* timings) {
    MethodScore m;
    m.method = name;
    m.rmse =
        warpResidualRmse(pair.frame1, pair.frame2, pair.intrinsics, result ? &result->scene_flow : nullptr, &excluded);
    if (result) {
      m.solved = true;
      m.segments = int(result->segments.size());
      m.label_trace = labelCountTrace(*result, true);
      m.timings = *timings;
    }
    scores.pixels = m.rmse.pixels;
    scores.methods.push_back(m);
  };
  add("zero flow", nullptr, nullptr);
  add("one label", &solves.one_label, &solves.one_label_time);
  add("MC-TV", &solves.tv, &solves.tv_time);
  add("MC-Quad", &solves.quad, &solves.quad_time);
  // The common mask guarantees one pixel set; a differing count would mean the mask and the metric disagree.
  for (const MethodScore& m : scores.methods)
    if (m.rmse.pixels != scores.pixels)
      throw InputError("scoreRealPair: '" + m.method + "' was scored on " + std::to_string(m.rmse.pixels) +
                       " pixels, the others on " + std::to_string(scores.pixels));
  return scores;
}

namespace {

std::string row(const std::string& pair, const std::string& method, double photometric, double geometric_mm,
                const std::string& segments, const StageTimings* t) {
  char line[512];
  if (t)
    std::snprintf(line, sizeof line, "%-20s %-9s %8.4f %8.2f %4s | %8.1f %7.1f %7.1f %7.1f %7.1f %7.1f %7.1f %7.1f\n",
                  pair.c_str(), method.c_str(), photometric, geometric_mm, segments.c_str(), t->total, t->preprocessing,
                  t->initialisation, t->motion, t->labels, t->adaptation, t->occlusion, t->outputs);
  else
    std::snprintf(line, sizeof line, "%-20s %-9s %8.4f %8.2f %4s | %8s %7s %7s %7s %7s %7s %7s %7s\n", pair.c_str(),
                  method.c_str(), photometric, geometric_mm, segments.c_str(), "-", "-", "-", "-", "-", "-", "-", "-");
  return line;
}

}  // namespace

std::string realBenchTable(const std::vector<PairScores>& scores) {
  std::string out;
  char line[512];
  std::snprintf(line, sizeof line, "%-20s %-9s %8s %8s %4s | %8s %7s %7s %7s %7s %7s %7s %7s\n", "pair", "method",
                "rmseI", "rmseZ_mm", "segs", "total_ms", "pyr", "init", "motion", "labels", "adapt", "occl", "output");
  out += line;
  for (const PairScores& p : scores) {
    for (const MethodScore& m : p.methods)
      out += row(p.pair, m.method, m.rmse.photometric, 1000.0 * m.rmse.geometric,
                 m.solved ? std::to_string(m.segments) : "-", m.solved ? &m.timings : nullptr);
    std::snprintf(line, sizeof line, "%-20s (%dx%d, %zu pixels scored)\n", "", p.width, p.height, p.pixels);
    out += line;
  }
  if (scores.empty()) return out;

  // Averages over pairs, method by method (the first pair gives the method order).
  for (const MethodScore& first : scores.front().methods) {
    double photometric = 0, geometric = 0, segments = 0;
    StageTimings mean;
    for (const PairScores& p : scores) {
      const MethodScore& m = p.method(first.method);
      photometric += m.rmse.photometric;
      geometric += m.rmse.geometric;
      segments += m.segments;
      for (double StageTimings::*s :
           {&StageTimings::preprocessing, &StageTimings::initialisation, &StageTimings::motion, &StageTimings::labels,
            &StageTimings::adaptation, &StageTimings::occlusion, &StageTimings::outputs, &StageTimings::total})
        mean.*s += m.timings.*s;
    }
    const double n = double(scores.size());
    for (double StageTimings::*s :
         {&StageTimings::preprocessing, &StageTimings::initialisation, &StageTimings::motion, &StageTimings::labels,
          &StageTimings::adaptation, &StageTimings::occlusion, &StageTimings::outputs, &StageTimings::total})
      mean.*s /= n;
    char segs[32];
    std::snprintf(segs, sizeof segs, "%.1f", segments / n);
    out += row("average", first.method, photometric / n, 1000.0 * geometric / n, first.solved ? segs : "-",
               first.solved ? &mean : nullptr);
  }
  out += "# motion labels over the outer iterations: K-means > after each update (-merged or removed +split)\n";
  for (const PairScores& p : scores)
    for (const MethodScore& m : p.methods)
      if (m.solved && m.method != "one label") {
        std::snprintf(line, sizeof line, "#   %-20s %-9s %s\n", p.pair.c_str(), m.method.c_str(),
                      m.label_trace.c_str());
        out += line;
      }
  return out;
}

std::vector<PairScores> benchRealPairs(const std::vector<std::string>& names,
                                       const std::function<RealPair(const std::string&)>& load, const Config& config,
                                       int repeat, ExclusionMask mask,
                                       const std::function<void(const std::string&)>& progress, std::string* backend) {
  std::vector<PairScores> scores;
  for (const std::string& name : names) {
    if (progress)
      progress("pair " + name + ": loading and solving (one label, MC-TV, MC-Quad; " + std::to_string(repeat) +
               " run(s) each)...");
    const RealPair pair = load(name);
    const PairSolves solves = solveRealPair(pair, config, repeat);
    if (backend) *backend = solves.quad.backend;
    scores.push_back(scoreRealPair(pair, solves, mask));
  }
  return scores;
}

}  // namespace mc_flow
