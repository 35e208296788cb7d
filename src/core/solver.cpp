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

#ifdef _OPENMP
#include <omp.h>
#endif

namespace mc_flow {

namespace {

using Clock = std::chrono::steady_clock;
double elapsedMs(Clock::time_point since) {
  return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

// Nearest-pixel resampling of a mask to another pyramid level (pixel-centre aligned). Levels differ by a
// power of two (integer halving drops an odd last column/row), so the scale is 2^k, not the size ratio.
ImageU8 resampleMask(const ImageU8& mask, int width, int height) {
  if (mask.sameSize(width, height)) return mask;
  ImageU8 out(width, height, 1, 0);
  const double scale = std::exp2(std::round(std::log2(double(mask.width) / double(width))));  // source px per target px
  for (int y = 0; y < height; ++y) {
    const int sy = std::clamp(int(std::floor((y + 0.5) * scale)), 0, mask.height - 1);
    for (int x = 0; x < width; ++x) {
      const int sx = std::clamp(int(std::floor((x + 0.5) * scale)), 0, mask.width - 1);
      out(x, y) = mask(sx, sy);
    }
  }
  return out;
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

// Labels of the label level carried to another pyramid level.
SoftLabels labelsAtLevel(const SoftLabels& u, int from_level, int to_level, const Pyramid& pyramid) {
  if (to_level == from_level) return u;
  if (to_level < from_level) return upsampleLabels(u, pyramid[to_level].points.width, pyramid[to_level].points.height);
  SoftLabels out = u;
  for (int level = from_level + 1; level <= to_level; ++level)
    out = downsampleLabels(out, pyramid[level].points.width, pyramid[level].points.height);
  return out;
}

double meanAbsoluteChange(const SoftLabels& a, const SoftLabels& b) {
  if (a.data.size() != b.data.size() || a.data.empty()) return 1.0;
  double sum = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) sum += std::fabs(a.data[i] - b.data[i]);
  return sum / double(a.planeSize());
}

}  // namespace

struct Solver::Impl {
  Config config;
  std::unique_ptr<LabelOptimizer> optimizer;
  std::unique_ptr<MotionAccumulator> motion;
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
  impl_->optimizer = makeLabelOptimizer(config.backend, &impl_->backend_note);
  impl_->motion = makeMotionAccumulator(impl_->optimizer->name() == "cuda" ? Backend::Cuda : Backend::Cpu);
}

Solver::~Solver() = default;

const Config& Solver::config() const { return impl_->config; }
std::string Solver::backendName() const { return impl_->optimizer->name(); }

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
  result.backend = impl_->optimizer->name();
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

  // ---- initialisation: K-means on 3D points, hard labels at the label level
  t = Clock::now();
  const PyramidLevel& L1 = pyr1[label_level];
  const int LW = L1.points.width, LH = L1.points.height;
  KMeansResult kmeans = kmeansPoints(pyr1[kmeans_level].points, config.initial_labels, config.kmeans_max_iterations,
                                     config.kmeans_tolerance, config.seed);
  if (kmeans.centres.empty()) kmeans = kmeansPoints(L1.points, config.initial_labels, config.kmeans_max_iterations,
                                                    config.kmeans_tolerance, config.seed);
  const ImageI32 assignment = assignToNearestCentre(L1.points, kmeans.centres);
  const int initial_motion_labels = std::max<int>(1, int(kmeans.centres.size()));
  SoftLabels u(LW, LH, initial_motion_labels + 1, 0.f);
  for (int y = 0; y < LH; ++y)
    for (int x = 0; x < LW; ++x) {
      const int a = assignment(x, y);
      u.at(a >= 0 ? a : u.outlier(), x, y) = 1.f;
    }
  // Every label starts from the dominant motion (one label over all valid pixels, coarse to fine down to the
  // label level): with a moving camera all labels then start near the truth, and a small segment that is
  // frozen at the coarse levels (too few pixels there) does not have to find a large motion from zero.
  Vector6d dominant = Vector6d::Zero();
  if (config.dominant_motion_init) {
    for (int level = levels - 1; level >= label_level; --level) {
      const PyramidLevel& P = pyr1[level];
      SoftLabels one(P.points.width, P.points.height, 2, 0.f);
      for (std::size_t k = 0; k < one.planeSize(); ++k) (std::isfinite(P.points.data[k * 3 + 2]) ? one.plane(0) : one.plane(1))[k] = 1.f;
      std::vector<Vector6d> single{dominant};
      estimateMotionsAtLevel(P, pyr2[level], one, nullptr, single, config, impl_->motion.get());
      dominant = single[0];
    }
  }
  std::vector<Vector6d> twists(std::size_t(initial_motion_labels), dominant);
  result.timings.initialisation = elapsedMs(t);
  impl_->progress("pyramid %d levels, labels at level %d, %d initial labels", levels, label_level, initial_motion_labels);

  LabelProblem problem;
  geometricWeights(L1, config.min_geometric_weight, problem.weight_x, problem.weight_y);
  LabelDual dual;
  ImageU8 occlusion(LW, LH, 1, 0);

  // ---- Algorithm 1
  for (int k = 0; k < config.outer_iterations; ++k) {
    OuterIterationStats stats;
    stats.iteration = k;
    stats.labels_before = u.count - 1;

    // 1. motion step, coarse to fine
    t = Clock::now();
    const int coarsest = k == 0 ? levels - 1 : std::min(levels - 1, finest + config.motion_coarse_levels_after_first);
    Config motion_config = config;
    if (k > 0) motion_config.motion_iterations_per_level = config.motion_iterations_refine;
    for (int level = coarsest; level >= finest; --level) {
      const SoftLabels u_level = labelsAtLevel(u, label_level, level, pyr1);
      const ImageU8 occ_level = resampleMask(occlusion, pyr1[level].points.width, pyr1[level].points.height);
      const MotionLevelStats ms = estimateMotionsAtLevel(pyr1[level], pyr2[level], u_level,
                                                         config.detect_occlusions ? &occ_level : nullptr, twists,
                                                         motion_config, impl_->motion.get());
      stats.motion_iterations += ms.iterations;
    }
    result.timings.motion += elapsedMs(t);

    // Labels whose motions came out alike are merged before the label step as well as after it: the
    // result is the same as merging one step later, but the label step then runs on a few labels, not 20.
    t = Clock::now();
    const ImageU8* occlusion_used = config.detect_occlusions ? &occlusion : nullptr;
    LabelCostModel early_model = labelCostModel(L1, pyr2[label_level], u, occlusion_used, twists, config, *impl_->motion);
    const AdaptationStats early = adaptLabelCount(u, twists, early_model, valid_label_level, config, false);
    stats.merged += early.merged;
    if (early.merged > 0) dual.reset(LW, LH, u.count);
    result.timings.adaptation += elapsedMs(t);

    // occlusion mask of the current motions (section 6)
    t = Clock::now();
    if (config.detect_occlusions) {
      const ImageF warped = warpPoints(L1.points, u, twists);
      occlusion = detectOcclusions(warped, pyr2[label_level].depth, L1.intrinsics, config);
    }
    result.timings.occlusion += elapsedMs(t);

    // 2. label step
    t = Clock::now();
    computeDataCosts(L1, pyr2[label_level], twists, config.detect_occlusions ? &occlusion : nullptr, config, problem);
    const SoftLabels u_before = u;
    const LabelStats ls = impl_->optimizer->optimize(problem, u, dual, config.label_iterations, config.label_tolerance);
    stats.label_iterations = ls.iterations;
    stats.energy = ls.energy;
    stats.label_change = meanAbsoluteChange(u_before, u);
    result.timings.labels += elapsedMs(t);

    // 3. update n: merges and removals on the energy, then (while a motion step follows) splits
    t = Clock::now();
    LabelCostModel model = labelCostModel(L1, pyr2[label_level], u, occlusion_used, twists, config, *impl_->motion);
    const AdaptationStats as = adaptLabelCount(u, twists, model, valid_label_level, config, true);
    stats.merged += as.merged;
    stats.removed = as.removed;
    stats.smallest_refused_merge = as.smallest_refused_merge;
    if (k + 1 < config.outer_iterations) {
      stats.split = proposeSplits(u, twists, L1, pyr2[label_level], occlusion_used, valid_label_level, config,
                                  *impl_->motion).split;
    }
    stats.labels_after = u.count - 1;
    if (as.merged + as.removed + stats.split > 0) dual.reset(LW, LH, u.count);
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
  ImageU8 occlusion_final = occlusion;
  {
    const PyramidLevel& F1 = pyr1[finest];
    t = Clock::now();
    u_final = labelsAtLevel(u, label_level, finest, pyr1);
    if (config.detect_occlusions)
      occlusion_final = detectOcclusions(warpPoints(F1.points, u_final, twists), pyr2[finest].depth, F1.intrinsics, config);
    result.timings.occlusion += elapsedMs(t);
    t = Clock::now();
    LabelProblem final_problem;
    geometricWeights(F1, config.min_geometric_weight, final_problem.weight_x, final_problem.weight_y);
    computeDataCosts(F1, pyr2[finest], twists, config.detect_occlusions ? &occlusion_final : nullptr, config,
                     final_problem);
    LabelDual final_dual;
    const LabelStats ls = impl_->optimizer->optimize(final_problem, u_final, final_dual, config.label_iterations_final,
                                                     config.label_tolerance);
    result.energy = ls.energy;
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
