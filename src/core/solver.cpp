// Algorithm 1 of the paper: K-means initialisation, then alternating motion step (coarse to fine),
// occlusion mask, label step and label-count update; a final label step at the processing level; outputs
// at the input resolution.
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

struct Solver::Impl {
  Config config;
  std::unique_ptr<SolveBackend> backend;
  std::string backend_note;

  template <typename... Args>
  void progress(const char* format, Args... args) const {
    if (!config.verbose) return;
    std::fprintf(stderr, "[mc_flow] ");
    std::fprintf(stderr, format, args...);
    std::fprintf(stderr, "\n");
  }
};

Solver::Solver(const Config& config) : impl_(std::make_unique<Impl>()) {
  config.validate();
  impl_->config = config;
  impl_->backend = makeSolveBackend(config.backend, &impl_->backend_note);
}

Solver::~Solver() = default;

const Config& Solver::config() const { return impl_->config; }
std::string Solver::backendName() const { return toString(impl_->backend->kind()); }
Backend Solver::backendKind() const { return impl_->backend->kind(); }

Result Solver::solve(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K) {
  const Config& config = impl_->config;
  const auto start = Clock::now();
  const ThreadCountScope thread_scope(config.threads);
  K.validate();
  frame1.validate("frame1");
  frame2.validate("frame2");
  if (frame1.width() != frame2.width() || frame1.height() != frame2.height())
    throw InputError("frame sizes differ: frame1 is " + std::to_string(frame1.width()) + "x" +
                     std::to_string(frame1.height()) + ", frame2 is " + std::to_string(frame2.width()) + "x" +
                     std::to_string(frame2.height()));

  Result result;
  result.width = frame1.width();
  result.height = frame1.height();
  result.intrinsics = K;
  result.backend_kind = impl_->backend->kind();
  result.backend = toString(result.backend_kind);
  result.backend_note = impl_->backend_note;

  // ---- preprocessing: pyramids
  auto t = Clock::now();
  const int levels = pyramidLevelCount(result.width, result.height, config.coarsest_min_width);
  if (config.processing_level >= levels)
    throw ConfigError("processing_level = " + std::to_string(config.processing_level) + " but a " +
                      std::to_string(result.width) + "x" + std::to_string(result.height) + " input has only " +
                      std::to_string(levels) + " pyramid levels");
  const Pyramid pyr1 = buildPyramid(frame1, K, levels, config);
  const Pyramid pyr2 = buildPyramid(frame2, K, levels, config);
  const int finest = config.processing_level;
  const int label_level = std::min(levels - 1, finest + config.label_level_offset);
  const int kmeans_level = std::min(levels - 1, label_level + config.kmeans_level_offset);
  result.pyramid_levels = levels;
  result.processing_width = pyr1[finest].points.width;
  result.processing_height = pyr1[finest].points.height;
  const int valid_label_level = pyr1[label_level].validCount();
  if (pyr1[finest].validCount() == 0 || valid_label_level == 0)
    throw InputError("frame1: no depth within [min_depth, max_depth] = [" + std::to_string(config.min_depth) + ", " +
                     std::to_string(config.max_depth) + "] m");
  result.timings.preprocessing = elapsedMs(t);

  // ---- initialisation: K-means on 3D points (a coarse level: a few hundred points, on the host), hard
  // labels at the label level
  t = Clock::now();
  SolveBackend& backend = *impl_->backend;
  backend.loadPyramids(pyr1, pyr2, config);
  KMeansResult kmeans = kmeansPoints(pyr1[kmeans_level].points, config.initial_labels, config.kmeans_max_iterations,
                                     config.kmeans_tolerance, config.seed);
  if (kmeans.centres.empty()) kmeans = kmeansPoints(pyr1[label_level].points, config.initial_labels,
                                                    config.kmeans_max_iterations, config.kmeans_tolerance, config.seed);
  backend.initialiseLabels(label_level, kmeans.centres);
  const int initial_motion_labels = backend.labelCount() - 1;
  // Every label starts from the dominant motion (one label over all valid pixels, coarse to fine down to the
  // label level): with a moving camera all labels then start near the truth, and a small segment that is
  // frozen at the coarse levels (too few pixels there) does not have to find a large motion from zero.
  Vector6d dominant = Vector6d::Zero();
  if (config.dominant_motion_init) {
    for (int level = levels - 1; level >= label_level; --level) {
      std::vector<Vector6d> single{dominant};
      estimateMotionsWith(backend.motionAccumulator(level, MotionLabels::AllValidAsOne, false, config), single, config);
      dominant = single[0];
    }
  }
  std::vector<Vector6d> twists(std::size_t(initial_motion_labels), dominant);
  result.timings.initialisation = elapsedMs(t);
  impl_->progress("pyramid %d levels, labels at level %d, %d initial labels", levels, label_level, initial_motion_labels);

  const bool occlusions = config.detect_occlusions;

  // ---- Algorithm 1
  for (int k = 0; k < config.outer_iterations; ++k) {
    OuterIterationStats stats;
    stats.iteration = k;
    stats.labels_before = backend.labelCount() - 1;

    // 1. motion step, coarse to fine
    t = Clock::now();
    const int coarsest = k == 0 ? levels - 1 : std::min(levels - 1, finest + config.motion_coarse_levels_after_first);
    Config motion_config = config;
    if (k > 0) motion_config.motion_iterations_per_level = config.motion_iterations_refine;
    for (int level = coarsest; level >= finest; --level) {
      MotionLevelStats ms = estimateMotionsWith(
          backend.motionAccumulator(level, MotionLabels::Current, occlusions, config), twists, motion_config);
      ms.level = level;
      stats.motion_iterations += ms.iterations;
      stats.motion_levels.push_back(ms);
    }
    result.timings.motion += elapsedMs(t);

    // Labels whose motions came out alike are merged before the label step as well as after it: the
    // result is the same as merging one step later, but the label step then runs on a few labels, not 20.
    t = Clock::now();
    LabelCostModel early_model = backend.costModel(twists, occlusions, config);
    const AdaptationStats early = adaptLabelCount(backend, twists, early_model, valid_label_level, config, false);
    stats.merged += early.merged;
    result.timings.adaptation += elapsedMs(t);

    // occlusion mask of the current motions (section 6)
    t = Clock::now();
    if (occlusions) backend.updateOcclusion(twists, config);
    result.timings.occlusion += elapsedMs(t);

    // 2. label step
    t = Clock::now();
    const LabelStepStats ls = backend.labelStep(twists, occlusions, config.label_iterations, config.label_tolerance, config);
    stats.label_iterations = ls.iterations;
    stats.energy = ls.energy;
    stats.label_change = ls.mean_change;
    result.timings.labels += elapsedMs(t);

    // 3. update n: merges and removals on the energy, then (while a motion step follows) splits
    t = Clock::now();
    LabelCostModel model = backend.costModel(twists, occlusions, config);
    const AdaptationStats as = adaptLabelCount(backend, twists, model, valid_label_level, config, true);
    stats.merged += as.merged;
    stats.removed = as.removed;
    stats.smallest_refused_merge = as.smallest_refused_merge;
    if (k + 1 < config.outer_iterations)
      stats.split = proposeSplits(backend, twists, occlusions, valid_label_level, config).split;
    stats.labels_after = backend.labelCount() - 1;
    result.timings.adaptation += elapsedMs(t);
    result.energy = ls.energy;
    result.iterations.push_back(stats);
    impl_->progress("outer iteration %d: %d motion labels (merged %d, removed %d, split %d; cheapest refused merge %.1f, label cost %.1f), label change %.5f",
                    k, stats.labels_after, stats.merged, stats.removed, stats.split, stats.smallest_refused_merge,
                    labelCost(config, valid_label_level), stats.label_change);
    if (k > 0 && as.merged + as.removed + stats.split == 0 && stats.label_change < config.outer_convergence) break;
  }

  // ---- final label step at the processing level (also when that is the label level: labels removed in the
  // last update handed their pixels to the outlier label, and only a label step gives them back)
  SoftLabels u_final;
  {
    t = Clock::now();
    backend.moveLabels(finest);
    if (occlusions) backend.updateOcclusion(twists, config);
    result.timings.occlusion += elapsedMs(t);
    t = Clock::now();
    const LabelStepStats ls =
        backend.labelStep(twists, occlusions, config.label_iterations_final, config.label_tolerance, config);
    result.energy = ls.energy;
    u_final = backend.downloadLabels();
    result.timings.labels += elapsedMs(t);
  }

  // ---- outputs at the input resolution
  t = Clock::now();
  const PyramidLevel& F0 = pyr1[0];
  result.soft_labels = finest == 0 ? u_final : upsampleLabels(u_final, result.width, result.height);
  // Pixels without depth belong to the outlier label whatever the upsampling blended in.
  for (int y = 0; y < result.height; ++y)
    for (int x = 0; x < result.width; ++x)
      if (!std::isfinite(F0.points(x, y, 2)))
        for (int i = 0; i < result.soft_labels.count; ++i)
          result.soft_labels.at(i, x, y) = i == result.soft_labels.outlier() ? 1.f : 0.f;
  const ImageF warped = warpPoints(F0.points, result.soft_labels, twists);
  sceneAndOpticalFlow(F0.points, warped, K, result.scene_flow, result.optical_flow);
  result.occlusion = config.detect_occlusions ? detectOcclusions(warped, pyr2[0].depth, K, config)
                                              : ImageU8(result.width, result.height, 1, 0);
  const ImageI32 argmax = result.soft_labels.argmax();
  result.labels = ImageI32(result.width, result.height, 1, 0);
  for (std::size_t i = 0; i < argmax.data.size(); ++i) {
    const int a = argmax.data[i];
    result.labels.data[i] = (a == result.soft_labels.outlier() || !std::isfinite(F0.points.data[i * 3 + 2])) ? 0 : a + 1;
  }
  const std::vector<Eigen::Vector3d> centroids = labelCentroids(result.soft_labels, F0.points);
  for (int i = 0; i < result.soft_labels.count - 1; ++i) {
    Segment s;
    s.id = i + 1;
    s.twist = twists[std::size_t(i)];
    s.transform = se3Exp(s.twist);
    s.support = result.soft_labels.support(i);
    s.centroid = centroids[std::size_t(i)];
    result.segments.push_back(s);
  }
  result.timings.outputs = elapsedMs(t);
  result.timings.total = elapsedMs(start);
  return result;
}

}  // namespace mc_flow
