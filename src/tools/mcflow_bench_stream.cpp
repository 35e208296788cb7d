// Stream-mode benchmark on synthetic sequences, or on a real one exported by `mcflow export-seq` (core only: runs on
// the GPU machine too). Each sequence is
// solved twice with persistent ids: cold (every pair from K-means, ids matched by overlap) and warm (each
// pair from the previous pair's segments and motions). Prints per mode: time per pair, optical-flow EPE,
// id consistency (the fraction of consecutive pairs in which each true part keeps the id most of its
// pixels carry), how many pairs after it starts moving the late box has a segment of its own, and how many
// warm starts fell back to a cold solve.
//
// --world (issue 28) runs each sequence through SequencePipeline instead (the same solves, stamped at 30 Hz) and
// prints a second table, per variant, mode and scene: "parts" is the sequence above, "static" the same camera path
// over the same room with every part moving with the room (SyntheticSceneOptions::parts_follow_room). Columns:
//   ate_mm, rpe_mm, rpe_deg  the odometry's camera path (SequencePipeline::odometry()) against the true one (the room's
//                            motion inverted and chained): ATE after a rigid alignment without scale, RPE per frame
//                            (evaluateTrajectory, the TUM RGB-D definitions); ate_ratio: parts / static ("-" when
//                            the static run's ATE is below 0.01 mm: a camera at rest, variants 0 and 1)
//   oracle_mm  the ATE of the same pairs' world motions refitted on the true room's pixels (oracleRoom: a perfect
//              segmentation); on the static scene the room is the whole view
//   world_ok   pairs whose world (Result::world.ids) covers the majority of the room's (part 0's) pixels with a
//              majority of its own pixels on the room (regionOverlap); pur_min: the least such share of any pair
//   mask_iou   the moving mask (movingMask) against the true one, the pixels of parts whose motion relative to the
//              room exceeds moving_min_speed or moving_min_rate at 30 Hz (worldVelocity on the true twists), per pair
//   lin_*, ang_*  each moving part's world velocity error [m/s at the part's centroid, deg/s] for the segment holding
//              most of its pixels, median and max over parts (>= 200 pixels) and pairs; `parts` counts them
//   nees_*     the world twist's NEES per pair (below); in95: the fraction of pairs within chi2_6's 95% interval
//              [1.24, 14.45] (0.95 when the covariance is right); mean_lo, mean_hi: the 95% interval of the mean NEES,
//              chi2_6N(0.025 and 0.975) / N over N pairs;
//              pose_nees: the mean over frames of the odometry pose's NEES (its accumulated covariance)
// The first table's columns keep their meaning under --world; only their timings include the pipeline's own work.
//
// --sequence DIR solves a real sequence exported by `mcflow export-seq` (PFM, no OpenCV: the GPU machine) as
// `mcflow run-seq` solves it (SequencePipeline, --downsample as run-seq's) instead of the synthetic ones, and prints
// per mode the time per pair (push: the pipeline's call, its downsampling included; solve: Result::timings.total), the
// segments per pair and the stage means; --trajectory FILE writes the camera's path as run-seq's trajectory.txt.
//
//   mcflow_bench_stream [--frames 30] [--variants 0,1,2] [--width 320] [--height 240] [--backend auto|cpu|cuda]
//                       [--modes cold,warm] [--noise] [--ids] [--world] [--set name=value ...]
//   mcflow_bench_stream --sequence DIR [--downsample 0] [--modes cold,warm] [--trajectory FILE] [--backend ...]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/core/soft_labels.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/core/static_world.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/eval/sequence_folder.h"
#include "mc_flow/eval/synthetic_scene.h"

using namespace mc_flow;

namespace {

struct Options {
  int frames = 30, width = 320, height = 240;
  std::vector<int> variants{0, 1, 2};
  std::vector<bool> warm_modes{false, true};
  bool noise = false;
  bool print_ids = false;   // per pair, the majority id of each true part (stderr)
  bool world = false;       // the static world's metrics (issue 28)
  OutputSelection outputs;  // --outputs required: no soft labels, no scene flow
  Config config;
  std::string sequence;    // --sequence DIR: a real sequence (mcflow export-seq) instead of the synthetic ones
  int downsample = 0;      // --downsample, as run-seq's
  std::string trajectory;  // --trajectory FILE: the camera's path (one mode only)
};

constexpr int kLatePart = 10;           // synthetic_scene.h: the box that starts moving at frame 10
constexpr int kLateStartPair = 10;      // the first pair in which it moves
constexpr int kMinPartPixels = 200;     // parts smaller than this in a pair are not judged
constexpr double kFrameRate = 30.0;     // [Hz] the --world runs' stamps: the moving thresholds are per second
constexpr double kMinStaticAte = 1e-5;  // [m] a static run's ATE below this (a camera at rest) gives no ATE ratio

struct ModeStats {
  std::vector<double> ms, epe;
  StageTimings stages;        // summed over the pairs after the first
  long kept = 0, judged = 0;  // id consistency
  int late_delay = -1;        // pairs after kLateStartPair until the late box has its own segment (-1: never)
  int fallbacks = 0, warm = 0;
};

// The static world's metrics of one sequence (--world).
struct WorldStats {
  StampedPoses truth, estimate;  // the camera's pose per frame (camera-to-odometry frame: the first frame's)
  StampedPoses oracle;           // the same with each pair's world motion fitted on the true room's pixels (oracleRoom)
  int pairs = 0, world_right = 0;
  double purity_min = 1;  // the least pure world of a pair: its share of room pixels
  std::vector<double> iou, linear_error, angular_error_deg;
  // NEES = e^T C^-1 e (nees()): per pair e = world.twist - the room's true twist (v [m], w [rad], the motion of the
  // world's points over the pair in the first frame's camera frame) with C = world.covariance; per frame e =
  // log(T_true^-1 T_odometry), the right perturbation odometry().pose_covariance describes. Both chi2 with 6 dof when
  // the estimate is unbiased and the covariance right.
  std::vector<double> nees_pair, nees_pose;
};

// The stage columns' sums: `s` added to `sum`.
void addStages(StageTimings& sum, const StageTimings& s) {
  sum.preprocessing += s.preprocessing;
  sum.initialisation += s.initialisation;
  sum.motion += s.motion;
  sum.labels += s.labels;
  sum.adaptation += s.adaptation;
  sum.merge_test += s.merge_test;
  sum.occlusion += s.occlusion;
  sum.outputs += s.outputs;
}

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
    const auto best =
        std::max_element(v.begin(), v.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
    out[part] = best->first;
  }
  return out;
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / double(v.size());
}

// A part's motion relative to the room as worldVelocity states it, at `centroid`: the same definition for the truth
// (the true twists) and the estimate (a segment's fit moved to the part's centroid).
WorldVelocity velocityAt(const Segment& segment, const Matrix6d& covariance, const StaticWorld& world,
                         const Eigen::Vector3d& centroid, const Config& config) {
  Segment at = segment;
  at.centroid = centroid;
  return worldVelocity(at, covariance, world, false, 1.0 / kFrameRate, config);
}

// The room's motion over a pair fitted as the static world's motion would be with a perfect segmentation: one robust
// rigid fit (the motion step, the world fit's depth noise model) on the pixels that truly move as the room does (the
// room, and the parts of the static sequence), the truly occluded
// ones left out, at the processing level from the true motion. What the odometry could reach on these
// frames if the segmentation were right: the ATE of the chained fits against the solver's tells what the
// segmentation costs, against the static sequence's what the moving parts take away by hiding the room.
Vector6d oracleRoom(const SyntheticPair& p, const Vector6d& start, const Config& config) {
  const int W = p.gt_parts.width, H = p.gt_parts.height;
  const Pyramid frame1 = buildPyramid(p.frame1, p.intrinsics, 1, config);
  const Pyramid frame2 = buildPyramid(p.frame2, p.intrinsics, 1, config);
  // The room and every part that moves exactly with it (all of them in the static sequence).
  std::map<int, bool> rigid_with_room;
  for (const SyntheticPart& part : p.parts) rigid_with_room[part.id] = part.twist == p.parts.front().twist;
  SoftLabels room(W, H, 2, 0.f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const auto known = rigid_with_room.find(p.gt_parts(x, y));
      const bool is_room = known != rigid_with_room.end() && known->second;
      room.at(0, x, y) = is_room ? 1.f : 0.f;
      room.at(1, x, y) = is_room ? 0.f : 1.f;
    }
  Config fit = config;
  fit.depth_noise_reference = config.world_depth_noise_reference;
  fit.motion_iterations_per_level = 20;  // to the fit's own optimum: no start may show through
  std::vector<Vector6d> twists{start};
  estimateMotionsAtLevel(frame1[0], frame2[0], room, &p.gt_occlusion, twists, fit);
  return twists[0];
}

// Scores one solved pair of the pipeline against the pair's ground truth (WorldStats).
void scoreWorld(const SyntheticPair& p, const SequenceStep& step, const Odometry& odometry, const Config& config,
                bool print, WorldStats& ws) {
  const Result& r = *step.result;
  const int W = p.gt_parts.width, H = p.gt_parts.height;
  ImageU8 valid(W, H, 1, 0);
  for (std::size_t k = 0; k < valid.data.size(); ++k) valid.data[k] = isValidDepth(p.frame1.depth.data[k]) ? 1 : 0;
  const Vector6d room = p.parts.front().twist;  // part 0: the room; its points moved by exp(room) over the pair
  StaticWorld true_world;
  true_world.twist = room;

  // The camera path: it moved by the inverse of the room's motion.
  const Eigen::Matrix4d previous = ws.truth.back().second;
  ws.truth.emplace_back(odometry.stamp, previous * se3Exp(room).inverse());
  ws.estimate.emplace_back(odometry.stamp, odometry.pose);
  const Eigen::Matrix4d oracle_before = ws.oracle.back().second;
  ws.oracle.emplace_back(odometry.stamp, oracle_before * se3Exp(-oracleRoom(p, room, config)));
  ws.nees_pose.push_back(
      nees(se3Log(Eigen::Matrix4d(ws.truth.back().second.inverse() * odometry.pose)), odometry.pose_covariance));
  ++ws.pairs;
  const RegionOverlap world = regionOverlap(r.labels, r.world.ids, p.gt_parts, 0, &valid);
  ws.world_right += r.world.found && world.matches();
  ws.purity_min = std::min(ws.purity_min, world.purity());
  if (r.world.found) ws.nees_pair.push_back(nees(r.world.twist - room, r.world.covariance));

  // Each part's pixels, centroid and the segment ids on them.
  struct Part {
    std::size_t pixels = 0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    std::map<int, std::size_t> votes;
  };
  std::map<int, Part> parts;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const std::size_t k = std::size_t(y) * W + x;
      if (!valid.data[k]) continue;
      Part& part = parts[p.gt_parts.data[k]];
      const double z = p.frame1.depth.data[k];
      const Intrinsics& K = p.intrinsics;
      part.sum += Eigen::Vector3d(z * (x - K.cx) / K.fx, z * (y - K.cy) / K.fy, z);
      ++part.pixels;
      if (r.labels.data[k] > 0) ++part.votes[r.labels.data[k]];
    }
  std::map<int, bool> moving;  // by part id
  for (const SyntheticPart& truth : p.parts) {
    const auto seen = parts.find(truth.id);
    if (truth.id == 0 || seen == parts.end()) continue;
    const Part& part = seen->second;
    const Eigen::Vector3d centroid = part.sum / double(part.pixels);
    Segment true_segment;
    true_segment.twist = truth.twist;
    true_segment.transform = se3Exp(truth.twist);
    const WorldVelocity v = velocityAt(true_segment, Matrix6d::Zero(), true_world, centroid, config);
    moving[truth.id] = v.moving;
    if (!v.moving || part.pixels < std::size_t(kMinPartPixels) || part.votes.empty()) continue;
    const int id = std::max_element(part.votes.begin(), part.votes.end(), [](const auto& a, const auto& b) {
                     return a.second < b.second;
                   })->first;
    const auto segment =
        std::find_if(r.segments.begin(), r.segments.end(), [id](const Segment& s) { return s.id == id; });
    if (segment == r.segments.end()) throw std::logic_error("label " + std::to_string(id) + " has no segment");
    const WorldVelocity e = velocityAt(*segment, segment->covariance, r.world, centroid, config);
    ws.linear_error.push_back((e.linear - v.linear).norm());
    ws.angular_error_deg.push_back((e.angular - v.angular).norm() * 180.0 / M_PI);
    if (print)
      std::fprintf(stderr, "  part %2d -> %2d: true %.3f m/s %.1f deg/s, error %.3f m/s %.1f deg/s\n", truth.id, id,
                   v.linear.norm(), v.angular.norm() * 180.0 / M_PI, ws.linear_error.back(),
                   ws.angular_error_deg.back());
  }
  ImageU8 truth_mask(W, H, 1, 0);
  for (std::size_t k = 0; k < truth_mask.data.size(); ++k) {
    const auto m = moving.find(p.gt_parts.data[k]);
    truth_mask.data[k] = m != moving.end() && m->second ? 255 : 0;
  }
  ws.iou.push_back(maskIou(movingMask(r, step.world_velocities), truth_mask, &valid));
  if (print) {
    std::fprintf(stderr, "  world %-8s ids", r.world.chosen_by.c_str());
    for (int id : r.world.ids) std::fprintf(stderr, " %d", id);
    std::fprintf(stderr, "  coverage %.3f purity %.3f  nees %.1f  iou %.3f\n", world.coverage(), world.purity(),
                 ws.nees_pair.empty() ? 0.0 : ws.nees_pair.back(), ws.iou.back());
  }
}

// `world`: run through SequencePipeline (frames stamped at kFrameRate) and score the static world into it; null: the
// solver alone.
ModeStats runSequence(const std::vector<SyntheticPair>& pairs, const Config& config, bool print_ids,
                      const OutputSelection& outputs, WorldStats* world = nullptr) {
  ModeStats st;
  std::unique_ptr<Solver> solver;
  Result previous;
  std::unique_ptr<SequencePipeline> pipeline;
  if (!world) {
    solver = std::make_unique<Solver>(config);
    solver->setOutputs(outputs);
  }
  if (world) {
    pipeline = std::make_unique<SequencePipeline>(config, 1, 1.0);  // downsample 1: the solver's input, as below
    pipeline->setOutputs(outputs);
    pipeline->push(StreamFrame{pairs.front().frame1, pairs.front().intrinsics, 0.0, "synthetic", {}});
    world->truth.emplace_back(0.0, Eigen::Matrix4d::Identity());
    world->estimate.emplace_back(0.0, Eigen::Matrix4d::Identity());
    world->oracle.emplace_back(0.0, Eigen::Matrix4d::Identity());
  }
  std::map<int, int> previous_ids;
  for (std::size_t t = 0; t < pairs.size(); ++t) {
    const SyntheticPair& p = pairs[t];
    Result solved;
    SequenceStep step;
    StreamFrame next;
    if (pipeline) next = StreamFrame{p.frame2, p.intrinsics, double(t + 1) / kFrameRate, "synthetic", {}};
    const auto start = std::chrono::steady_clock::now();
    if (pipeline) {
      step = pipeline->push(std::move(next));
    } else {
      solved = t == 0 ? solver->solve(p.frame1, p.frame2, p.intrinsics)
                      : solver->solve(p.frame1, p.frame2, p.intrinsics, previous);
    }
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (pipeline && step.outcome != SequenceStep::Outcome::Solved)
      throw std::runtime_error("pair " + std::to_string(t) + ": " + toString(step.outcome) + " " + step.problem);
    const Result& r = pipeline ? *step.result : solved;
    if (t > 0) {  // the first pair is cold in both modes
      st.ms.push_back(ms);
      addStages(st.stages, r.timings);
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
    if (world) scoreWorld(p, step, pipeline->odometry(), config, print_ids, *world);
    previous_ids = ids;
    if (!pipeline) {
      // As a stream does (SequencePipeline): the result before the previous one gives its image memory to the next
      // solve's outputs (without it every pair's outputs would land on fresh pages).
      if (t > 0) solver->recycle(std::move(previous));
      previous = std::move(solved);
    }
  }
  return st;
}

std::vector<SyntheticPair> renderSequence(const Options& opt, int variant, bool parts_follow_room) {
  std::vector<SyntheticPair> pairs;
  for (int t = 0; t + 1 < opt.frames; ++t) {
    SyntheticSceneOptions so;
    so.width = opt.width;
    so.height = opt.height;
    so.variant = variant;
    so.first_frame = t;
    so.stream_events = true;
    so.parts_follow_room = parts_follow_room;
    if (opt.noise) so.addSensorNoise();
    pairs.push_back(renderSyntheticPair(so));
  }
  return pairs;
}

double maxOf(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); }

// A real sequence (--sequence): every frame through SequencePipeline as run-seq pushes it, in one mode.
int runRealSequence(const Options& opt, const SequenceFolder& folder, bool warm) {
  Config config = opt.config;
  config.warm_start = warm;
  SequencePipeline pipeline(config, opt.downsample, 1.0);  // run-seq's default --max-pair-interval
  if (!pipeline.backendUnavailable().empty())  // the CPU's timings must not pass for the requested backend's
    throw BackendError("backend '" + toString(config.backend) + "' cannot be used: " + pipeline.backendUnavailable());
  pipeline.setOutputs(opt.outputs);
  std::vector<double> push_ms, solve_ms, segments;
  StageTimings stages;
  int warm_starts = 0, fallbacks = 0, failed = 0, processing_width = 0, processing_height = 0;
  std::string trajectory;
  for (std::size_t i = 0; i < folder.stamps.size(); ++i) {
    StreamFrame frame{folder.frame(i), folder.K, folder.stamps[i], folder.dir, {}};  // read before the clock starts
    const auto start = std::chrono::steady_clock::now();
    const SequenceStep step = pipeline.push(std::move(frame));
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (step.outcome == SequenceStep::Outcome::PairFailed) ++failed;
    if (step.outcome != SequenceStep::Outcome::Solved) continue;
    const Result& r = *step.result;
    if (trajectory.empty()) trajectory = io::tumTrajectoryLine(step.first->stamp, Eigen::Matrix4d::Identity());
    trajectory += io::tumTrajectoryLine(step.second->stamp, pipeline.odometry().pose);
    processing_width = r.processing_width;
    processing_height = r.processing_height;
    segments.push_back(double(r.segments.size()));
    if (step.pair_index == 0) continue;  // the first pair is cold in both modes: not timed
    push_ms.push_back(ms);
    solve_ms.push_back(r.timings.total);
    addStages(stages, r.timings);
    warm_starts += r.start == StartKind::Warm;
    fallbacks += r.start == StartKind::ColdFallback;
  }
  if (!opt.trajectory.empty()) io::writeTextFile(opt.trajectory, trajectory);
  const double p90 = percentile(push_ms, 0.9);
  const double n = std::max<double>(1.0, double(push_ms.size()));
  std::printf(
      "%-5s %9s %6zu %8.1f %9.1f %7.1f %7.1f %9.1f %8.1f %8.0f %6d %9d %6d   %.1f %.1f %.1f %.1f %.1f %.1f %.1f %.2f\n",
      warm ? "warm" : "cold", (std::to_string(processing_width) + "x" + std::to_string(processing_height)).c_str(),
      push_ms.size(), mean(push_ms), median(push_ms), p90, maxOf(push_ms), median(solve_ms), median(segments),
      maxOf(segments), warm_starts, fallbacks, failed, stages.preprocessing / n, stages.initialisation / n,
      stages.motion / n, stages.labels / n, stages.adaptation / n, stages.occlusion / n, stages.outputs / n,
      stages.merge_test / n);
  std::fflush(stdout);
  return failed == 0 ? 0 : 1;
}

struct WorldRow {
  int variant = 0;
  bool warm = false;
  const char* scene = "";
  WorldStats stats;
  double ate_ratio = -1;  // parts / static; < 0: not printed
};

void printWorldTable(const std::vector<WorldRow>& rows, const Config& config) {
  std::printf(
      "\nstatic world (--world): frames at %.0f Hz; moving = faster than %.3f m/s or %.1f deg/s relative to "
      "the room; lin [m/s], ang [deg/s]\n",
      kFrameRate, config.moving_min_speed, config.moving_min_rate);
  std::printf("%-8s %-5s %-6s %5s %8s %9s %9s %7s %8s %8s %7s %8s %6s %8s %8s %8s %8s %8s %9s %7s %8s %8s %9s\n",
              "variant", "mode", "scene", "pairs", "ate_mm", "ate_ratio", "oracle_mm", "rpe_mm", "rpe_deg", "world_ok",
              "pur_min", "mask_iou", "parts", "lin_med", "lin_max", "ang_med", "ang_max", "nees_med", "nees_mean",
              "in95", "mean_lo", "mean_hi", "pose_nees");
  const double lo6 = chiSquareQuantile(6, 0.025), hi6 = chiSquareQuantile(6, 0.975);
  for (const WorldRow& row : rows) {
    const WorldStats& w = row.stats;
    const TrajectoryErrors e = evaluateTrajectory(w.truth, w.estimate, 1e-3, 0.0);
    int inside = 0;
    for (double n : w.nees_pair) inside += n >= lo6 && n <= hi6;
    const double n = double(std::max<std::size_t>(1, w.nees_pair.size()));
    // The mean of N NEES of 6 dof times N is chi2 with 6 N dof (independent pairs): its 95% interval.
    const double mean_lo = w.nees_pair.empty() ? 0.0 : chiSquareQuantile(6.0 * n, 0.025) / n;
    const double mean_hi = w.nees_pair.empty() ? 0.0 : chiSquareQuantile(6.0 * n, 0.975) / n;
    char ratio[16] = "-";
    if (row.ate_ratio >= 0) std::snprintf(ratio, sizeof ratio, "%.2f", row.ate_ratio);
    std::printf(
        "%-8d %-5s %-6s %5d %8.2f %9s %9.2f %7.2f %8.3f %8.3f %7.3f %8.3f %6zu %8.4f %8.4f %8.2f %8.2f %8.1f %9.1f "
        "%7.2f %8.2f %8.2f %9.1f\n",
        row.variant, row.warm ? "warm" : "cold", row.scene, w.pairs, 1e3 * e.ate_rmse_m, ratio,
        1e3 * evaluateTrajectory(w.truth, w.oracle, 1e-3, 0.0).ate_rmse_m, 1e3 * e.rpe_frame_trans_m,
        e.rpe_frame_rot_deg, double(w.world_right) / std::max(1, w.pairs), w.purity_min, mean(w.iou),
        w.linear_error.size(), median(w.linear_error), maxOf(w.linear_error), median(w.angular_error_deg),
        maxOf(w.angular_error_deg), median(w.nees_pair), mean(w.nees_pair), double(inside) / n, mean_lo, mean_hi,
        mean(w.nees_pose));
  }
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  CommandLine line("mcflow_bench_stream", {{"frames", true, "frames per sequence (>= 3, default 30)"},
                                           {"variants", true, "comma-separated synthetic variants (default 0,1,2)"},
                                           {"width", true, "image width (default 320)"},
                                           {"height", true, "image height (default 240)"},
                                           {"backend", true, "auto | cpu | cuda"},
                                           {"modes", true, "comma-separated: cold, warm (default both)"},
                                           {"noise", false, "Kinect-like intensity and depth noise"},
                                           {"ids", false, "print each pair's majority id per true part on stderr"},
                                           {"world", false,
                                            "the static world: odometry ATE/RPE (with and without moving parts), world "
                                            "choice, moving mask, world velocities, NEES (a second table)"},
                                           {"outputs", true,
                                            "all | required (default all): with required the solves leave out the "
                                            "soft labels and the scene flow (OutputSelection), as the nodelet does "
                                            "when nobody subscribes to them"},
                                           {"sequence", true,
                                            "DIR: a real sequence written by `mcflow export-seq` (PFM), solved as "
                                            "`mcflow run-seq` solves it, instead of the synthetic sequences"},
                                           {"downsample", true,
                                            "with --sequence: input pixels per processing pixel, as run-seq's (0 = "
                                            "towards 320 px wide, default)"},
                                           {"trajectory", true,
                                            "with --sequence and one mode: write the camera's path to FILE (TUM "
                                            "RGB-D format, as run-seq's trajectory.txt)"}});
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
    opt.world = line.has("world");
    const std::string outputs = line.text("outputs", "all");
    if (outputs != "all" && outputs != "required")
      throw ConfigError("--outputs: '" + outputs + "' is neither all nor required");
    opt.outputs.soft_labels = opt.outputs.scene_flow = outputs == "all";
    line.applySettings(opt.config);
    opt.config.validate();
    opt.sequence = line.text("sequence", "");
    opt.downsample = line.integer("downsample", 0, 0, 1 << 20);
    chooseDownsample(opt.downsample, 320);  // 0 or a power of two, as SequencePipeline takes it
    opt.trajectory = line.text("trajectory", "");
    if (opt.sequence.empty() && (line.has("downsample") || line.has("trajectory")))
      throw ConfigError("--downsample and --trajectory are for --sequence");
    if (!opt.trajectory.empty() && opt.warm_modes.size() != 1)
      throw ConfigError("--trajectory needs one mode (--modes warm or --modes cold)");
    if (!opt.sequence.empty())
      for (const char* synthetic : {"frames", "variants", "width", "height", "noise", "ids", "world"})
        if (line.has(synthetic))
          throw ConfigError(std::string("--") + synthetic + " is for the synthetic sequences, not --sequence");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcflow_bench_stream: %s\n%s", e.what(), line.usage().c_str());
    return 2;
  }
  if (!opt.sequence.empty()) {
    int code = 0;
    try {
      const SequenceFolder folder = readSequenceFolder(opt.sequence);
      const RgbdFrame first = folder.frame(0);
      std::printf("# mcflow_bench_stream --sequence %s: %zu frames of %dx%d, downsample %d, backend %s\n",
                  opt.sequence.c_str(), folder.stamps.size(), first.width(), first.height(), opt.downsample,
                  toString(opt.config.backend).c_str());
      std::printf("%-5s %9s %6s %8s %9s %7s %7s %9s %8s %8s %6s %9s %6s   %s\n", "mode", "process", "pairs", "mean_ms",
                  "median_ms", "p90_ms", "max_ms", "solve_med", "segs_med", "segs_max", "warm", "fallbacks", "failed",
                  "mean stage ms: pyramid init motion labels count occl outputs merge");
      for (const bool warm : opt.warm_modes) code = std::max(code, runRealSequence(opt, folder, warm));
    } catch (const std::exception& e) {  // a missing or malformed file, a pair the solver refused
      std::fprintf(stderr, "mcflow_bench_stream: %s\n", e.what());
      return 1;
    }
    return code;
  }
  std::printf("%-8s %-5s %6s %9s %9s %9s %8s %9s %9s %6s   %s\n", "variant", "mode", "pairs", "mean_ms", "median_ms",
              "mean_epe", "id_keep", "late_pairs", "fallbacks", "warm",
              "mean stage ms: pyramid init motion labels count occl outputs merge");
  std::vector<WorldRow> world_rows;
  for (const int variant : opt.variants) {
    const std::vector<SyntheticPair> pairs = renderSequence(opt, variant, false);
    std::vector<SyntheticPair> static_pairs;
    if (opt.world) static_pairs = renderSequence(opt, variant, true);
    for (const bool warm : opt.warm_modes) {
      Config config = opt.config;
      config.warm_start = warm;
      WorldRow parts_row{variant, warm, "parts", {}, -1};
      const ModeStats st =
          runSequence(pairs, config, opt.print_ids, opt.outputs, opt.world ? &parts_row.stats : nullptr);
      if (opt.world) {
        WorldRow static_row{variant, warm, "static", {}, -1};
        runSequence(static_pairs, config, false, opt.outputs, &static_row.stats);
        const WorldStats& a = parts_row.stats;
        const WorldStats& b = static_row.stats;
        const double parts_ate = evaluateTrajectory(a.truth, a.estimate, 1e-3, 0.0).ate_rmse_m;
        const double static_ate = evaluateTrajectory(b.truth, b.estimate, 1e-3, 0.0).ate_rmse_m;
        parts_row.ate_ratio = static_ate > kMinStaticAte ? parts_ate / static_ate : -1;
        world_rows.push_back(std::move(parts_row));
        world_rows.push_back(std::move(static_row));
      }
      const double n = std::max<double>(1.0, double(st.ms.size()));
      const StageTimings& s = st.stages;
      std::printf("%-8d %-5s %6zu %9.1f %9.1f %9.4f %8.3f %9d %9d %6d   %.1f %.1f %.1f %.1f %.1f %.1f %.1f %.2f\n",
                  variant, warm ? "warm" : "cold", pairs.size(), mean(st.ms), median(st.ms), mean(st.epe),
                  st.judged ? double(st.kept) / double(st.judged) : 0.0, st.late_delay, st.fallbacks, st.warm,
                  s.preprocessing / n, s.initialisation / n, s.motion / n, s.labels / n, s.adaptation / n,
                  s.occlusion / n, s.outputs / n, s.merge_test / n);
      std::fflush(stdout);
    }
  }
  if (opt.world) printWorldTable(world_rows, opt.config);
  return 0;
}
