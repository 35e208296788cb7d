// Algorithm 1 of the paper: K-means initialisation (or, in a stream, the previous pair's segments carried
// forward), then alternating motion step (coarse to fine), occlusion mask, label step and label-count update;
// a final label step at the processing level; outputs at the input resolution.
#include "mc_flow/core/solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "mc_flow/core/error.h"
#include "mc_flow/core/kmeans.h"
#include "mc_flow/core/label_adaptation.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/occlusion.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/scene_flow.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/static_world.h"
#include "mc_flow/core/warm_start.h"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace mc_flow {

namespace {

using Clock = std::chrono::steady_clock;
double elapsedMs(Clock::time_point since) {
  return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

// Config::threads for the duration of one solve; the caller's OpenMP setting is restored afterwards.
class ThreadCountScope {
 public:
  explicit ThreadCountScope(int threads) {
#ifdef _OPENMP
    previous_ = omp_get_max_threads();
    if (threads > 0) omp_set_num_threads(threads);
#else
    (void)threads;
#endif
  }
  ~ThreadCountScope() {
#ifdef _OPENMP
    omp_set_num_threads(previous_);
#endif
  }
  ThreadCountScope(const ThreadCountScope&) = delete;
  ThreadCountScope& operator=(const ThreadCountScope&) = delete;

 private:
  int previous_ = 1;
};

}  // namespace

namespace {

// The levels a solve works at (the pyramids themselves live in the backend).
struct Prepared {
  int width = 0, height = 0;  // input
  int levels = 0, finest = 0, label_level = 0, kmeans_level = 0, valid_label_level = 0;
};

// What Algorithm 1 starts from: the backend's labels (set by coldStart or warmStart), one twist per motion label.
struct Start {
  ImageI32 hard;  // a warm start's carried labels at the label level (a cold start assigns on the backend)
  int motion_labels = 0;
  std::vector<Vector6d> twists;
  // A warm start's carried labels: labels 0..size-1 are the previous pair's segments, these their lineages in order.
  std::vector<LabelLineage> carried_lineage;
  int outer_iterations = 1;
  int label_iterations = 1, label_iterations_final = 1;  // per label step inside the loop / the final one
  int first_motion_coarsest = 0;                         // the first motion step's coarsest level
  bool first_motion_refines = false;                     // the first motion step uses motion_iterations_refine
  // The first motion step drops weak label couplings (motion_min_coupling): K-means' labels, whose seams are cuts
  // through rigid parts; from the first label step on the labels' blends are its decisions, and every coupling counts.
  bool first_motion_drops_weak_couplings = false;
};

}  // namespace

std::string toString(StartKind start) {
  switch (start) {
    case StartKind::Cold: return "cold";
    case StartKind::Warm: return "warm";
    case StartKind::ColdFallback: return "cold_fallback";
  }
  return "unknown";
}

struct Solver::Impl {
  Config config;
  std::unique_ptr<SolveBackend> backend;
  std::string backend_note;
  Result spare;  // a finished result (Solver::recycle) whose image memory the next solve's outputs reuse
  OutputSelection selection;

  template <typename... Args>
  void progress(const char* format, Args... args) const {
    if (!config.verbose) return;
    std::fprintf(stderr, "[mc_flow] ");
    std::fprintf(stderr, format, args...);
    std::fprintf(stderr, "\n");
  }

  Result run(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, const Result* previous,
             const Eigen::Matrix4d* camera_motion_prior = nullptr);
  // Checks the input, picks the levels and has the backend build both pyramids.
  Prepared prepare(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K);
  // A result with the sizes, levels and backend of a solve filled in.
  Result emptyResult(const Prepared& p, const Intrinsics& K);
  Start coldStart(const Prepared& p, Result& result);
  Start warmStart(const Prepared& p, const CarriedLabels& carried, const Result& previous, Result& result);
  // Algorithm 1 from `start`, the final label step and the outputs (segments numbered 1..m).
  void iterate(const Prepared& p, Start start, Result& result);
};

Solver::Solver(const Config& config) : impl_(std::make_unique<Impl>()) {
  config.validate();
  impl_->config = config;
  impl_->backend = makeSolveBackend(config.backend, &impl_->backend_note, config.cuda_device);
}

Solver::Solver(const Config& config, std::unique_ptr<SolveBackend> backend, std::string backend_note)
    : impl_(std::make_unique<Impl>()) {
  config.validate();
  if (!backend) throw ConfigError("Solver: the solve backend given is null");
  impl_->config = config;
  impl_->backend = std::move(backend);
  impl_->backend_note = std::move(backend_note);
}

Solver::~Solver() = default;

void Solver::recycle(Result&& finished) {
  impl_->spare = std::move(finished);
  finished = Result();  // not a half-moved result: images with sizes but no data
}

void Solver::setOutputs(const OutputSelection& selection) { impl_->selection = selection; }
const OutputSelection& Solver::outputs() const { return impl_->selection; }

const Config& Solver::config() const { return impl_->config; }
std::string Solver::backendName() const { return toString(impl_->backend->kind()); }
Backend Solver::backendKind() const { return impl_->backend->kind(); }

Result Solver::solve(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K) {
  return impl_->run(frame1, frame2, K, nullptr);
}

Result Solver::solve(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, const Result& previous) {
  return impl_->run(frame1, frame2, K, &previous);
}

Result Solver::solve(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, const Result* previous,
                     const Eigen::Matrix4d& camera_motion_prior) {
  if (!camera_motion_prior.allFinite()) throw InputError("camera motion prior: not finite");
  return impl_->run(frame1, frame2, K, previous, &camera_motion_prior);
}

Prepared Solver::Impl::prepare(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K) {
  K.validate();
  frame1.validate("frame1");
  frame2.validate("frame2");
  if (frame1.width() != frame2.width() || frame1.height() != frame2.height())
    throw InputError("frame sizes differ: frame1 is " + std::to_string(frame1.width()) + "x" +
                     std::to_string(frame1.height()) + ", frame2 is " + std::to_string(frame2.width()) + "x" +
                     std::to_string(frame2.height()));
  Prepared p;
  p.width = frame1.width();
  p.height = frame1.height();
  p.levels = pyramidLevelCount(p.width, p.height, config.coarsest_min_width);
  if (config.processing_level >= p.levels)
    throw ConfigError("processing_level = " + std::to_string(config.processing_level) + " but a " +
                      std::to_string(p.width) + "x" + std::to_string(p.height) + " input has only " +
                      std::to_string(p.levels) + " pyramid levels");
  backend->buildPyramids(frame1, frame2, K, p.levels, config);
  p.finest = config.processing_level;
  p.label_level = std::min(p.levels - 1, p.finest + config.label_level_offset);
  p.kmeans_level = std::min(p.levels - 1, p.label_level + config.kmeans_level_offset);
  const std::vector<int>& valid = backend->validCounts();
  p.valid_label_level = valid[std::size_t(p.label_level)];
  if (valid[std::size_t(p.finest)] == 0 || p.valid_label_level == 0)
    throw InputError("frame1: no depth within [min_depth, max_depth] = [" + std::to_string(config.min_depth) + ", " +
                     std::to_string(config.max_depth) + "] m");
  return p;
}

Result Solver::Impl::emptyResult(const Prepared& p, const Intrinsics& K) {
  Result result;
  // The output images' memory of a recycled result (their contents are overwritten by the outputs stage).
  result.soft_labels.data.swap(spare.soft_labels.data);
  result.labels.data.swap(spare.labels.data);
  result.occlusion.data.swap(spare.occlusion.data);
  result.scene_flow.data.swap(spare.scene_flow.data);
  result.optical_flow.data.swap(spare.optical_flow.data);
  result.moved_depth.data.swap(spare.moved_depth.data);
  // The dormant regions' memory too, empty: only a stream pair's ids fill them (assignStreamIds).
  result.dormant_regions.data.swap(spare.dormant_regions.data);
  result.dormant_regions.data.clear();
  // 0x0 images (their sizes stay 0 until the outputs stage fills them) whose data keeps the recycled size, so that the
  // CUDA outputs can copy into it in chunks on several threads where the size is the same (fillOutputImages).
  result.width = p.width;
  result.height = p.height;
  result.intrinsics = K;
  result.backend_kind = backend->kind();
  result.backend = toString(result.backend_kind);
  result.backend_note = backend_note;
  result.pyramid_levels = p.levels;
  result.processing_width = pyramidLevelExtent(p.width, p.finest);
  result.processing_height = pyramidLevelExtent(p.height, p.finest);
  result.valid_pixels = backend->validCounts()[std::size_t(p.finest)];
  return result;
}

Result Solver::Impl::run(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, const Result* previous,
                         const Eigen::Matrix4d* camera_motion_prior) {
  const auto start_time = Clock::now();
  const ThreadCountScope thread_scope(config.threads);
  backend->activate();  // this thread may not have used the backend's device before
  auto t = Clock::now();
  const Prepared p = prepare(frame1, frame2, K);
  Result result = emptyResult(p, K);
  result.timings.preprocessing = elapsedMs(t);

  // Stream mode: the previous pair's segments on this frame 1 (for the warm start, or only for the ids), where the
  // backend has frame 1 (the CUDA backend on the device, the CPU one on the host's frame), with the label level's hard
  // labels for a warm start.
  CarriedSegments carried;
  if (previous) {
    t = Clock::now();
    carried = backend->carrySegments(*previous, frame1.depth, config.warm_start ? p.label_level : -1, config);
    result.timings.initialisation += elapsedMs(t);
  }

  auto solveCold = [&](Result& r) { iterate(p, coldStart(p, r), r); };

  if (previous && config.warm_start) {
    if (carried.labels.coverage() < config.warm_min_coverage) {
      result.start = StartKind::ColdFallback;
      result.start_note = "the previous segments cover " + std::to_string(carried.labels.coverage()) +
                          " of the valid pixels, below warm_min_coverage = " + std::to_string(config.warm_min_coverage);
      solveCold(result);
    } else {
      iterate(p, warmStart(p, carried.labels, *previous, result), result);
      result.start = StartKind::Warm;
      const double warm_per_pixel = result.energy / std::max(1, result.valid_pixels);
      const double previous_per_pixel = previous->energy / std::max(1, previous->valid_pixels);
      if (previous->valid_pixels > 0 && warm_per_pixel > config.warm_max_energy_ratio * previous_per_pixel) {
        // The carried solution explains this pair much worse than the previous one was explained: a jump,
        // a reset or a new scene. A cold solve decides.
        Result cold = emptyResult(p, K);
        cold.timings = result.timings;
        solveCold(cold);
        const std::string why = "warm energy per pixel " + std::to_string(warm_per_pixel) +
                                " > warm_max_energy_ratio x " + std::to_string(previous_per_pixel);
        if (cold.energy < result.energy) {
          cold.start = StartKind::ColdFallback;
          cold.start_note = why + "; the cold solve's energy is lower";
          result = std::move(cold);
        } else {
          // The backend now holds the cold solve's labels: the warm start is solved again (the same result) so that
          // what reads the backend after this (the static world) reads the labels of the result that is kept. Rare:
          // a jump whose cold solve did no better.
          Result again = emptyResult(p, K);
          again.timings = cold.timings;
          iterate(p, warmStart(p, carried.labels, *previous, again), again);
          again.start = StartKind::Warm;
          again.start_note = why + "; a cold solve did not do better, the warm result is kept";
          result = std::move(again);
        }
      }
    }
  } else {
    solveCold(result);
  }

  // Persistent ids: by overlap with the previous pair's segments carried into this frame 1, warm or cold.
  // (The labels themselves merge and split during the solve; what persists is the region a person sees.)
  if (previous)
    assignStreamIds(result, carried.ids, carried.dormant, *previous, config.id_min_overlap, config.id_memory_pairs);

  // The static world (by the stream's world ids, which need the ids above) and its motion on the union of its segments,
  // on the labels the outputs came from.
  t = Clock::now();
  std::vector<Matrix6d> covariances;
  // Which segment is in front of which, on frame 1's points at the coarsest level from the processing level on that is
  // still at least 160 pixels wide (a host pass of about 160x120 pixels from 320x240 or 640x480 input; the edges of a
  // thing worth a segment are still tens of pixels there). The result's ids are at the input resolution: 2^level apart.
  DepthOrder depth_order;
  if (result.segments.size() >= 2 && config.world_front_share > 0) {
    int order_level = p.finest;
    while (order_level + 1 < p.levels && pyramidLevelExtent(p.width, order_level + 1) >= 160) ++order_level;
    depth_order = depthOrderOf(result.labels, result.segments, backend->framePoints(order_level), 1 << order_level,
                               config.world_depth_edge);
  }
  result.world = estimateStaticWorld(*backend, result.segments, previous ? previous->world.ids : std::vector<int>(),
                                     camera_motion_prior, config.detect_occlusions, config, covariances, &depth_order);
  for (std::size_t i = 0; i < result.segments.size(); ++i) result.segments[i].covariance = covariances[i];
  result.timings.adaptation += elapsedMs(t);
  result.timings.total = elapsedMs(start_time);
  return result;
}

Start Solver::Impl::coldStart(const Prepared& p, Result& result) {
  // K-means on 3D points at a coarse level (a few hundred to a few thousand points; the CUDA backend runs it on the
  // device and downloads only the centres), assigned at the label level.
  const auto t = Clock::now();
  std::vector<Eigen::Vector3f> centres = backend->kmeansCentres(
      p.kmeans_level, config.initial_labels, config.kmeans_max_iterations, config.kmeans_tolerance, config.seed);
  // Every label starts from the dominant motion (one label over all valid pixels, coarse to fine down to the
  // label level): with a moving camera all labels then start near the truth, and a small segment that is
  // frozen at the coarse levels (too few pixels there) does not have to find a large motion from zero.
  Vector6d dominant = Vector6d::Zero();
  if (config.dominant_motion_init) {
    for (int level = p.levels - 1; level >= p.label_level; --level) {
      std::vector<Vector6d> single{dominant};
      estimateMotionsWith(backend->motionAccumulator(level, MotionLabels::AllValidAsOne, false, config), single,
                          config);
      dominant = single[0];
    }
  }
  if (centres.empty())
    centres = backend->kmeansCentres(p.label_level, config.initial_labels, config.kmeans_max_iterations,
                                     config.kmeans_tolerance, config.seed);
  Start start;
  start.motion_labels = std::max(1, int(centres.size()));
  if (centres.empty()) {  // no valid point at either level (prepare() refuses such a pair): all outliers
    const ImageF& points = backend->framePoints(p.label_level);
    backend->initialiseLabels(p.label_level, ImageI32(points.width, points.height, 1, -1), 1);
  } else {
    backend->initialiseLabelsFromCentres(p.label_level, centres);
  }
  start.twists.assign(std::size_t(start.motion_labels), dominant);
  start.outer_iterations = config.outer_iterations;
  start.label_iterations = config.label_iterations;
  start.label_iterations_final = config.label_iterations_final;
  start.first_motion_coarsest = p.levels - 1;
  start.first_motion_drops_weak_couplings = true;
  result.timings.initialisation += elapsedMs(t);
  progress("pyramid %d levels, labels at level %d, %d initial labels (K-means)", p.levels, p.label_level,
           start.motion_labels);
  return start;
}

Start Solver::Impl::warmStart(const Prepared& p, const CarriedLabels& carried, const Result& previous, Result& result) {
  const auto t = Clock::now();
  Start start;
  start.hard = carried.hard;  // a copy: a warm start solved again after a cold one starts from it too
  // Constant velocity: each carried segment starts from its previous motion.
  std::vector<double> covered(carried.ids.size(), 0.0);
  for (const int h : start.hard.data)
    if (h >= 0) covered[std::size_t(h)] += 1;
  for (const int id : carried.ids) {
    LabelLineage lineage;
    lineage.carried = true;
    for (const Segment& s : previous.segments)
      if (s.id == id) {
        lineage.previous_twist = s.twist;
        lineage.previous_centroid = s.centroid;
      }
    start.twists.push_back(lineage.previous_twist);
    start.carried_lineage.push_back(lineage);
  }
  // The widest carried segment's motion for the new clusters; none carried (possible with warm_min_coverage = 0): zero.
  const Vector6d widest =
      covered.empty() ? Vector6d::Zero()
                      : start.twists[std::size_t(std::max_element(covered.begin(), covered.end()) - covered.begin())];
  // Pixels no carried segment covers (new surfaces, parts entering the view): K-means among them alone, as
  // many clusters as their share of the initial labels; too few of them stay with the outlier label, which
  // the label step hands to their neighbours.
  const int uncovered = carried.valid - carried.covered;
  const double min_new = std::max(32.0, config.min_support_fraction * double(carried.valid));
  if (uncovered >= min_new) {  // the K-means where frame 1's points are (on the GPU: on the device)
    const int clusters = std::clamp(int(std::lround(config.initial_labels * double(uncovered) / carried.valid)), 1,
                                    config.initial_labels);
    const int kept = backend->initialiseLabelsWithUncoveredClusters(p.label_level, start.hard, int(start.twists.size()),
                                                                    clusters, config);
    for (int c = 0; c < kept; ++c) start.twists.push_back(widest);
  } else {
    backend->initialiseLabels(p.label_level, start.hard, int(start.twists.size()));
  }
  start.motion_labels = int(start.twists.size());
  backend->holdCarriedLabels(int(start.carried_lineage.size()));
  start.outer_iterations = config.warm_outer_iterations;
  start.label_iterations = config.warm_label_iterations;
  start.label_iterations_final = config.warm_label_iterations_final;
  start.first_motion_coarsest = std::min(p.levels - 1, p.finest + config.warm_motion_coarse_levels);
  start.first_motion_refines = true;
  result.timings.initialisation += elapsedMs(t);
  progress("warm start: %d carried segments cover %.3f of the valid pixels, %d new labels", int(carried.ids.size()),
           carried.coverage(), start.motion_labels - int(carried.ids.size()));
  return start;
}

void Solver::Impl::iterate(const Prepared& p, Start start, Result& result) {
  SolveBackend& labels = *backend;
  const bool occlusions = config.detect_occlusions;
  const int finest = p.finest;
  std::vector<Vector6d>& twists = start.twists;
  // Which labels descend from the previous pair's segments, and those segments' motions (merging two of them pays
  // warm_switch_cost; the merge test remembers how they moved).
  std::vector<LabelLineage> lineage(twists.size());
  std::copy_n(start.carried_lineage.begin(), std::min(lineage.size(), start.carried_lineage.size()), lineage.begin());
  std::vector<LabelLineage>* lineage_or_null = start.carried_lineage.empty() ? nullptr : &lineage;
  // The label-count update on the energy at the current twists (tiny labels removed when `remove_small`); `model`
  // receives the cost model it decided on.
  auto updateCount = [&](bool remove_small, LabelCostModel& model) {
    model = labels.costModel(twists, occlusions, config);
    return adaptLabelCount(labels, twists, model, p.valid_label_level, config, remove_small, lineage_or_null);
  };
  auto t = Clock::now();

  // ---- Algorithm 1. An outer iteration that split labels is followed by another (up to the larger of the start's
  // and Config::outer_iterations), so that new labels always get a motion step of their own: a warm start's single
  // outer iteration can still split off a part that starts moving.
  const int most_outer = std::max(start.outer_iterations, config.outer_iterations);
  bool split_last = false;
  for (int k = 0; k < most_outer; ++k) {
    if (k >= start.outer_iterations && !split_last) break;
    OuterIterationStats stats;
    stats.iteration = k;
    stats.labels_before = labels.labelCount() - 1;

    // 1. motion step, coarse to fine
    t = Clock::now();
    const int coarsest =
        k == 0 ? start.first_motion_coarsest : std::min(p.levels - 1, finest + config.motion_coarse_levels_after_first);
    Config motion_config = config;
    if (k > 0 || start.first_motion_refines)
      motion_config.motion_iterations_per_level = config.motion_iterations_refine;
    if (k > 0 || !start.first_motion_drops_weak_couplings) motion_config.motion_min_coupling = 0.0;
    for (int level = coarsest; level >= finest; --level) {
      MotionLevelStats ms = estimateMotionsWith(
          labels.motionAccumulator(level, MotionLabels::Current, occlusions, config), twists, motion_config);
      ms.level = level;
      stats.motion_iterations += ms.iterations;
      stats.motion_levels.push_back(ms);
    }
    result.timings.motion += elapsedMs(t);

    // Labels whose motions came out alike are merged before the label step as well as after it: the
    // result is the same as merging one step later, but the label step then runs on a few labels, not 20.
    t = Clock::now();
    LabelCostModel early_model;
    stats.merged += updateCount(false, early_model).merged;
    // Labels whose pixels the largest label's motion explains as well (Config::merge_occlusion_absorbers), from the
    // second outer iteration on: in the first, small labels' motions are still poor, and merging them there cost the
    // pairs with people their residuals (docs/ACCURACY.md). It leaves the occlusion mask of the labels it returns.
    const bool absorber_check = config.merge_occlusion_absorbers && occlusions && k > 0;
    if (absorber_check)
      stats.merged += mergeOcclusionAbsorbers(labels, twists, p.valid_label_level, config, lineage_or_null).merged;
    result.timings.adaptation += elapsedMs(t);

    // occlusion mask of the current motions (section 6)
    t = Clock::now();
    if (occlusions && !absorber_check) labels.updateOcclusion(twists, config);
    result.timings.occlusion += elapsedMs(t);

    // 2. label step
    t = Clock::now();
    const LabelStepStats ls =
        labels.labelStep(twists, occlusions, start.label_iterations, config.label_tolerance, config);
    stats.label_iterations = ls.iterations;
    stats.energy = ls.energy;
    stats.label_change = ls.mean_change;
    result.timings.labels += elapsedMs(t);

    // 3. update n: merges and removals on the energy, then (while a motion step follows) splits
    t = Clock::now();
    LabelCostModel model;
    const AdaptationStats as = updateCount(true, model);
    stats.merged += as.merged;
    stats.removed = as.removed;
    stats.smallest_refused_merge = as.smallest_refused_merge;
    // One rigid thing, one segment: pairs that one refitted motion explains within their noise merge, carried
    // segments too (no switching cost), so that a stream's splits cannot accumulate.
    // The update's cost model is the labels' own where it changed nothing: the merge test needs no pass for it.
    const bool unchanged = as.merged + as.removed == 0;
    const auto merge_start = Clock::now();
    const AdaptationStats explained = mergeWhereOneMotionExplains(
        labels, twists, p.valid_label_level, occlusions, config, lineage_or_null, unchanged ? &model : nullptr);
    result.timings.merge_test += elapsedMs(merge_start);
    stats.merged += explained.merged;
    stats.merge_rounds = explained.rounds;
    stats.merge_pairs_tested = explained.pairs_tested;
    if (k + 1 < most_outer) {
      stats.split = proposeSplits(labels, twists, occlusions, p.valid_label_level, config).split;
      lineage.resize(twists.size());  // split-off halves are new segments
    }
    split_last = stats.split > 0;
    stats.labels_after = labels.labelCount() - 1;
    result.timings.adaptation += elapsedMs(t);
    result.energy = ls.energy;
    result.iterations.push_back(stats);
    progress(
        "outer iteration %d: %d motion labels (merged %d, removed %d, split %d; cheapest refused merge %.1f, label "
        "cost %.1f), label change %.5f",
        k, stats.labels_after, stats.merged, stats.removed, stats.split, stats.smallest_refused_merge,
        labelCost(config, p.valid_label_level), stats.label_change);
    if (k > 0 && as.merged + explained.merged + as.removed + stats.split == 0 &&
        stats.label_change < config.outer_convergence)
      break;
  }

  // ---- final label step at the processing level (also when that is the label level: labels removed in the
  // last update handed their pixels to the outlier label, and only a label step gives them back)
  t = Clock::now();
  labels.moveLabels(finest);
  if (occlusions) labels.updateOcclusion(twists, config);
  result.timings.occlusion += elapsedMs(t);
  t = Clock::now();
  const LabelStepStats final_step =
      labels.labelStep(twists, occlusions, start.label_iterations_final, config.label_tolerance, config);
  result.energy = final_step.energy;
  result.timings.labels += elapsedMs(t);

  // Segments are numbered 1..m here; a stream solve gives them persistent ids afterwards (assignStreamIds).
  result.next_id = int(twists.size()) + 1;
  result.merged_ids.clear();
  result.ended_ids.clear();

  // ---- outputs at the input resolution
  t = Clock::now();
  labels.outputs(twists, config, selection, result);
  for (std::size_t i = 0; i < result.segments.size(); ++i) {
    Segment& s = result.segments[i];
    s.id = int(i) + 1;
    s.twist = twists[i];
    s.transform = se3Exp(s.twist);
  }
  result.timings.outputs += elapsedMs(t);
}

std::string labelCountTrace(const Result& result, bool changes) {
  std::string trace = result.iterations.empty() ? "-" : std::to_string(result.iterations.front().labels_before);
  for (const OuterIterationStats& it : result.iterations) {
    trace += " > " + std::to_string(it.labels_after);
    if (changes) trace += "(-" + std::to_string(it.merged + it.removed) + "+" + std::to_string(it.split) + ")";
  }
  return trace;
}

}  // namespace mc_flow
