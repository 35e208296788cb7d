// The CUDA solve backend (cuda/solve_backend.cu) against the CPU one (src/core/solve_backend.cpp), stage by
// stage, driven through the same sequence of SolveBackend calls on the same frames, at awkward sizes.
//
// Tolerances. The pyramids (frame 1's points, the valid counts) must agree bit for bit: both backends run the
// per-pixel rules of pyramid_pixel.h with every float operation rounded on its own. Discrete results (initial hard
// labels, which pixels a cut moves, label counts) must agree exactly. Sums over pixels run in another order (supports,
// moments, normal equations: relative 1e-6 of the largest entry). The label step's data costs use the device's log1pf
// (a few float ulps from the CPU's log1p), so u after a label step agrees to 1e-3 and the energy to a relative 1e-5.
#include <gtest/gtest.h>

#include "same_outputs.h"
#include "skip_without_gpu.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "core/stream_frames.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/kmeans.h"
#include "mc_flow/core/label_adaptation.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/testing/same_result.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace mc_flow {
namespace {

double maxAbsDifference(const SoftLabels& a, const SoftLabels& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.count, b.count);
  if (a.data.size() != b.data.size()) return INFINITY;
  double d = 0;
  for (std::size_t i = 0; i < a.data.size(); ++i) d = std::max(d, double(std::fabs(a.data[i] - b.data[i])));
  return d;
}

// A rendered synthetic pair (`variant`, width x height) with its whole pyramid built on both backends; returns the
// level count.
int buildBothPyramids(SolveBackend& cpu, SolveBackend& gpu, int width, int height, int variant, const Config& config) {
  SyntheticSceneOptions options;
  options.width = width;
  options.height = height;
  options.variant = variant;
  const SyntheticPair pair = renderSyntheticPair(options);
  const int levels = pyramidLevelCount(width, height, config.coarsest_min_width);
  for (SolveBackend* b : {&cpu, &gpu}) b->buildPyramids(pair.frame1, pair.frame2, pair.intrinsics, levels, config);
  return levels;
}

// The same values bit for bit (NaN matches NaN of the same bits).
bool sameBits(const ImageF& a, const ImageF& b) {
  return a.width == b.width && a.height == b.height && a.channels == b.channels &&
         std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(float)) == 0;
}

// Largest |a - b| where both are finite; counts the values finite in only one of them.
double maxFiniteDifference(const ImageF& a, const ImageF& b, int& finite_in_one) {
  finite_in_one = 0;
  double d = 0;
  if (a.data.size() != b.data.size()) return INFINITY;
  for (std::size_t i = 0; i < a.data.size(); ++i) {
    const bool fa = std::isfinite(a.data[i]), fb = std::isfinite(b.data[i]);
    if (fa != fb) ++finite_in_one;
    if (fa && fb) d = std::max(d, double(std::fabs(a.data[i] - b.data[i])));
  }
  return d;
}

// Outputs of both backends from labels that agree to the label step's 2e-3: flows within 1e-4 (px, m), the
// ids and the occlusion mask on all but a few pixels where two labels are within rounding of a tie or a point
// sits on the occlusion test's threshold.
void expectSameOutputs(const Result& a, const Result& b) {
  ASSERT_EQ(a.soft_labels.count, b.soft_labels.count);
  EXPECT_LE(maxAbsDifference(a.soft_labels, b.soft_labels), 2e-3) << "soft labels at level 0";
  int one_sided = 0;
  EXPECT_LE(maxFiniteDifference(a.scene_flow, b.scene_flow, one_sided), 1e-4) << "scene flow [m]";
  EXPECT_EQ(one_sided, 0) << "scene flow defined on one backend only";
  EXPECT_LE(maxFiniteDifference(a.optical_flow, b.optical_flow, one_sided), 1e-3) << "optical flow [px]";
  EXPECT_EQ(one_sided, 0) << "optical flow defined on one backend only";
  EXPECT_LE(maxFiniteDifference(a.moved_depth, b.moved_depth, one_sided), 1e-4) << "moved depth [m]";
  EXPECT_EQ(one_sided, 0);
  const std::size_t pixels = a.labels.data.size();
  ASSERT_EQ(pixels, b.labels.data.size());
  std::size_t id_differs = 0, mask_differs = 0;
  for (std::size_t k = 0; k < pixels; ++k) {
    id_differs += a.labels.data[k] != b.labels.data[k] ? 1 : 0;
    mask_differs += a.occlusion.data[k] != b.occlusion.data[k] ? 1 : 0;
  }
  EXPECT_LE(double(id_differs), 1e-3 * double(pixels)) << id_differs << " ids differ";
  EXPECT_LE(double(mask_differs), 2e-3 * double(pixels)) << mask_differs << " occlusion mask values differ";
  ASSERT_EQ(a.segments.size(), b.segments.size());
  for (std::size_t i = 0; i < a.segments.size(); ++i) {
    EXPECT_NEAR(a.segments[i].support, b.segments[i].support, 1e-3 * std::max(1.0, a.segments[i].support));
    EXPECT_LE((a.segments[i].centroid - b.segments[i].centroid).norm(), 1e-4) << "centroid of label " << i;
  }
}

template <typename A, typename B>
void expectRelativelyClose(const A& a, const B& b, double tolerance, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  double scale = 1e-30, diff = 0;
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    scale = std::max(scale, std::fabs(a(i)));
    diff = std::max(diff, std::fabs(a(i) - b(i)));
  }
  EXPECT_LE(diff, tolerance * scale) << what << ": largest difference " << diff << ", largest entry " << scale;
}

struct Scene {
  SyntheticPair pair;
  Pyramid p1, p2;
  std::vector<Eigen::Vector3f> centres;
};

Scene makeScene(int width, int height, int variant) {
  SyntheticSceneOptions options;
  options.width = width;
  options.height = height;
  options.variant = variant;
  Scene s;
  s.pair = renderSyntheticPair(options);
  Config config;
  const int levels = pyramidLevelCount(width, height, config.coarsest_min_width);
  s.p1 = buildPyramid(s.pair.frame1, s.pair.intrinsics, levels, config);
  s.p2 = buildPyramid(s.pair.frame2, s.pair.intrinsics, levels, config);
  s.centres = kmeansPoints(s.p1[std::min(levels - 1, 2)].points, 5, 20, 1e-4, 7).centres;
  return s;
}

void expectSameEquations(SolveBackend& cpu, SolveBackend& gpu, int level, MotionLabels which, bool occlusion,
                         const std::vector<Vector6d>& twists, const Config& config, const std::string& what) {
  MotionNormalEquations a, b;
  cpu.motionAccumulator(level, which, occlusion, config).accumulate(twists, a);
  gpu.motionAccumulator(level, which, occlusion, config).accumulate(twists, b);
  EXPECT_EQ(a.pixels, b.pixels) << what;
  expectRelativelyClose(a.H.reshaped(), b.H.reshaped(), 1e-6, what + " H");
  expectRelativelyClose(a.g, b.g, 1e-6, what + " g");
  expectRelativelyClose(a.label_cost, b.label_cost, 1e-6, what + " label costs");
}

// A label store that forwards to a backend but for its device-only shortcuts. HostLoop: refitUnions runs its host loop
// over the backend's single passes (neither refitUnionsWhereTheSumsAre nor the batched costModels forwarded).
// ChoiceOnTheHost: both forwarded, but not refitPairsWhereTheSumsAre, so refitPairsFromTheBetterMotion chooses the
// starts on the host from the backend's batched swapped pass and refits through the backend's refitUnions.
class ForwardingStore final : public LabelStore {
 public:
  enum class Mode { HostLoop, ChoiceOnTheHost };
  ForwardingStore(LabelStore& store, Mode mode) : store_(store), batched_(mode == Mode::ChoiceOnTheHost) {}
  int labelCount() const override { return store_.labelCount(); }
  std::vector<double> supports() override { return store_.supports(); }
  void remap(const std::vector<int>& target, int new_count) override { store_.remap(target, new_count); }
  std::vector<LabelMoments> ownedMoments() override { return store_.ownedMoments(); }
  CutTrial trialCuts(const std::vector<LabelCut>& cuts, const std::vector<Vector6d>& twists, bool use_occlusion,
                     const Config& config) override {
    return store_.trialCuts(cuts, twists, use_occlusion, config);
  }
  void applyCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) override {
    store_.applyCuts(cuts, use_occlusion, config);
  }
  LabelCostModel costModel(const std::vector<Vector6d>& twists, bool use_occlusion, const Config& config) override {
    return store_.costModel(twists, use_occlusion, config);
  }
  std::vector<LabelCostModel> costModels(const std::vector<std::vector<Vector6d>>& twist_sets, bool use_occlusion,
                                         const Config& config) override {
    return batched_ ? store_.costModels(twist_sets, use_occlusion, config)
                    : LabelStore::costModels(twist_sets, use_occlusion, config);
  }
  bool refitUnionsWhereTheSumsAre(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& groups,
                                  const std::vector<int>& batches, const std::vector<Vector6d>& starts, int iterations,
                                  bool use_occlusion, const Config& config, std::vector<UnionFit>& fits) override {
    return batched_ &&
           store_.refitUnionsWhereTheSumsAre(twists, groups, batches, starts, iterations, use_occlusion, config, fits);
  }

 private:
  LabelStore& store_;
  bool batched_;
};

// The whole sequence of stage calls a solve makes, on both backends, compared after each.
// With `carried_labels` > 0 the first labels are held as carried from a previous pair (a warm start): every label step
// adds the switching cost, and the carried labels follow the remap and the moves between levels.
void compareStages(int width, int height, int variant, int carried_labels = 0) {
  const Scene s = makeScene(width, height, variant);
  SCOPED_TRACE(std::to_string(width) + "x" + std::to_string(height) + " variant " + std::to_string(variant) +
               ", carried labels " + std::to_string(carried_labels));
  ASSERT_GE(s.centres.size(), 3u);
  Config config;
  auto cpu = makeCpuSolveBackend();
  auto gpu = makeCudaSolveBackend();
  const int levels = s.p1.size();
  const int label_level = std::min(levels - 1, 1);
  for (SolveBackend* b : {cpu.get(), gpu.get()})
    b->buildPyramids(s.pair.frame1, s.pair.frame2, s.pair.intrinsics, levels, config);
  // The host's nearest-centre assignment against the device's (initialiseLabelsFromCentres, as a cold solve calls it).
  cpu->initialiseLabels(label_level, assignToNearestCentre(s.p1[label_level].points, s.centres), int(s.centres.size()));
  gpu->initialiseLabelsFromCentres(label_level, s.centres);
  EXPECT_EQ(cpu->validCounts(), gpu->validCounts());
  for (int level = 0; level < levels; ++level)
    EXPECT_TRUE(sameBits(cpu->framePoints(level), gpu->framePoints(level))) << "frame 1's points at level " << level;
  ASSERT_EQ(cpu->labelCount(), gpu->labelCount());
  EXPECT_EQ(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 0.0) << "initial hard labels";
  if (carried_labels > 0) {
    config.warm_switch_cost = 0.2;
    for (SolveBackend* b : {cpu.get(), gpu.get()}) b->holdCarriedLabels(carried_labels);
  }

  const int n = cpu->labelCount() - 1;
  std::vector<Vector6d> twists;
  for (int i = 0; i < n; ++i) {
    Vector6d xi;
    xi << 0.01 * i, -0.004 * i, 0.006, 0.003 * i, -0.002, 0.001 * i;
    twists.push_back(xi);
  }
  // Motion step at the label level, a coarser level (2x2 means) and a finer one (bilinear), and the
  // dominant-motion labelling.
  expectSameEquations(*cpu, *gpu, label_level, MotionLabels::Current, false, twists, config, "label level");
  if (label_level + 1 < levels)
    expectSameEquations(*cpu, *gpu, label_level + 1, MotionLabels::Current, false, twists, config, "coarser level");
  expectSameEquations(*cpu, *gpu, 0, MotionLabels::Current, false, twists, config, "finer level");
  expectSameEquations(*cpu, *gpu, 0, MotionLabels::AllValidAsOne, false, {twists[0]}, config, "one label");

  // Occlusion, then a label step that uses it (data costs, weights, primal-dual).
  for (SolveBackend* b : {cpu.get(), gpu.get()}) b->updateOcclusion(twists, config);
  expectSameEquations(*cpu, *gpu, label_level, MotionLabels::Current, true, twists, config, "with occlusion");
  if (label_level + 1 < levels)
    expectSameEquations(*cpu, *gpu, label_level + 1, MotionLabels::Current, true, twists, config,
                        "coarser level with occlusion");
  const LabelStepStats la = cpu->labelStep(twists, true, 60, 0.0, config);
  const LabelStepStats lb = gpu->labelStep(twists, true, 60, 0.0, config);
  EXPECT_EQ(la.iterations, lb.iterations);
  EXPECT_NEAR(la.energy, lb.energy, 1e-5 * std::fabs(la.energy));
  EXPECT_NEAR(la.mean_change, lb.mean_change, 1e-4 * std::max(1.0, la.mean_change));
  EXPECT_LE(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 1e-3) << "after a label step";
  if (carried_labels > 0) {  // the held labels did something: the same step without them ends elsewhere
    auto plain = makeCpuSolveBackend();
    plain->buildPyramids(s.pair.frame1, s.pair.frame2, s.pair.intrinsics, levels, config);
    plain->initialiseLabels(label_level, assignToNearestCentre(s.p1[label_level].points, s.centres),
                            int(s.centres.size()));
    plain->updateOcclusion(twists, config);
    plain->labelStep(twists, true, 60, 0.0, config);
    EXPECT_GT(maxAbsDifference(plain->downloadLabels(), cpu->downloadLabels()), 0.05)
        << "the switching cost changed nothing";
  }

  // Label store: supports, moments, cost model.
  const std::vector<double> sa = cpu->supports(), sb = gpu->supports();
  expectRelativelyClose(Eigen::Map<const Eigen::VectorXd>(sa.data(), Eigen::Index(sa.size())),
                        Eigen::Map<const Eigen::VectorXd>(sb.data(), Eigen::Index(sb.size())), 1e-3, "supports");
  // Moments of owned pixels (u >= 0.5): computed on the same u as the CPU's only up to the label step's
  // rounding, so count those that agree on the labels first.
  const std::vector<LabelMoments> ma = cpu->ownedMoments(), mb = gpu->ownedMoments();
  ASSERT_EQ(ma.size(), mb.size());
  for (std::size_t i = 0; i < ma.size(); ++i)
    EXPECT_NEAR(ma[i].count, mb[i].count, std::max(2.0, 1e-3 * ma[i].count)) << "owned pixels of label " << i;
  const LabelCostModel ca = cpu->costModel(twists, true, config), cb = gpu->costModel(twists, true, config);
  for (int i = 0; i < n; ++i)
    expectRelativelyClose(ca.curvature[std::size_t(i)].reshaped(), cb.curvature[std::size_t(i)].reshaped(), 1e-3,
                          "curvature of label " + std::to_string(i));

  // Batched cost models (one launch): each batch's model is the same pass alone, bit for bit.
  {
    std::vector<Vector6d> other = twists;
    for (Vector6d& xi : other) xi += Vector6d::Constant(0.001);
    const std::vector<LabelCostModel> both = gpu->costModels({twists, other}, true, config);
    ASSERT_EQ(both.size(), 2u);
    const LabelCostModel alone = gpu->costModel(other, true, config);
    for (int i = 0; i < n; ++i) {
      EXPECT_EQ(both[0].cost[std::size_t(i)], cb.cost[std::size_t(i)]) << "label " << i;
      EXPECT_EQ(both[1].cost[std::size_t(i)], alone.cost[std::size_t(i)]) << "label " << i;
      EXPECT_EQ(both[1].curvature[std::size_t(i)], alone.curvature[std::size_t(i)]) << "label " << i;
      EXPECT_EQ(both[1].gradient[std::size_t(i)], alone.gradient[std::size_t(i)]) << "label " << i;
    }
  }

  // refitUnions: the device's loop (one wait) against the host's loop over the same backend's passes (a store that
  // forwards everything but refitUnionsWhereTheSumsAre and costModels; they differ by the 6x6 solve's rounding and
  // the left Jacobian's float rounding), and against the CPU backend. Group {1, 2} shares labels with both others: a
  // second batch.
  if (n >= 3) {
    const std::vector<std::vector<int>> groups = {{0, 1}, {2}, {1, 2}};
    const std::vector<Vector6d> starts = {twists[1], twists[2] + Vector6d::Constant(0.002), twists[2]};
    const std::vector<UnionFit> host_loop = [&] {
      ForwardingStore forward(*gpu, ForwardingStore::Mode::HostLoop);
      return refitUnions(forward, twists, groups, starts, 3, true, config);
    }();
    const std::vector<UnionFit> device = refitUnions(*gpu, twists, groups, starts, 3, true, config);
    const std::vector<UnionFit> cpu_fits = refitUnions(*cpu, twists, groups, starts, 3, true, config);
    ASSERT_EQ(device.size(), 3u);
    for (std::size_t g = 0; g < groups.size(); ++g) {
      SCOPED_TRACE("group " + std::to_string(g));
      EXPECT_EQ(device[g].iterations, host_loop[g].iterations);
      EXPECT_LT((device[g].twist - host_loop[g].twist).cwiseAbs().maxCoeff(), 1e-7) << device[g].twist.transpose();
      EXPECT_NEAR(device[g].cost, host_loop[g].cost, 1e-6 * std::fabs(host_loop[g].cost));
      EXPECT_NEAR(device[g].pixels, host_loop[g].pixels, 1e-6 * host_loop[g].pixels);
      ASSERT_EQ(device[g].member_cost.size(), groups[g].size());
      for (std::size_t m = 0; m < groups[g].size(); ++m)
        EXPECT_NEAR(device[g].member_cost[m], host_loop[g].member_cost[m], 1e-6 * std::fabs(host_loop[g].cost));
      expectRelativelyClose(device[g].curvature.reshaped(), host_loop[g].curvature.reshaped(), 1e-6, "curvature");
      EXPECT_EQ(device[g].iterations, cpu_fits[g].iterations);
      EXPECT_LT((device[g].twist - cpu_fits[g].twist).cwiseAbs().maxCoeff(), 1e-5) << cpu_fits[g].twist.transpose();
      EXPECT_NEAR(device[g].cost, cpu_fits[g].cost, 1e-4 * std::fabs(cpu_fits[g].cost));
    }
    EXPECT_GT(device[0].iterations, 0) << "the union's fit took no step: the test shows little";

    // refitPairsFromTheBetterMotion: the device's choice of each pair's start (no wait between the passes) against the
    // host's choice over the same backend's passes, bit for bit, and against the CPU backend. Three pairs of three
    // labels: three batches; label 2's twist moved so that the starts differ.
    std::vector<Vector6d> moved = twists;
    moved[2] += Vector6d::Constant(0.003);
    const std::vector<std::vector<int>> pairs = {{0, 1}, {1, 2}, {2, 0}};
    const std::vector<int> pair_batches = unionBatches(pairs);
    EXPECT_EQ(pair_batches, (std::vector<int>{0, 1, 2}));
    const std::vector<double> own = gpu->costModel(moved, true, config).cost;
    const std::vector<UnionFit> on_device =
        refitPairsFromTheBetterMotion(*gpu, moved, pairs, pair_batches, own, 2, true, config);
    const std::vector<UnionFit> chosen_on_host = [&] {
      ForwardingStore forward(*gpu, ForwardingStore::Mode::ChoiceOnTheHost);
      return refitPairsFromTheBetterMotion(forward, moved, pairs, pair_batches, own, 2, true, config);
    }();
    const std::vector<UnionFit> on_cpu = refitPairsFromTheBetterMotion(
        *cpu, moved, pairs, pair_batches, cpu->costModel(moved, true, config).cost, 2, true, config);
    ASSERT_EQ(on_device.size(), pairs.size());
    ASSERT_EQ(chosen_on_host.size(), pairs.size());
    for (std::size_t p = 0; p < pairs.size(); ++p) {
      SCOPED_TRACE("pair " + std::to_string(p));
      EXPECT_EQ(on_device[p].twist, chosen_on_host[p].twist);
      EXPECT_EQ(on_device[p].cost, chosen_on_host[p].cost);
      EXPECT_EQ(on_device[p].iterations, chosen_on_host[p].iterations);
      EXPECT_EQ(on_device[p].member_cost, chosen_on_host[p].member_cost);
      EXPECT_EQ(on_device[p].curvature, chosen_on_host[p].curvature);
      EXPECT_EQ(on_device[p].iterations, on_cpu[p].iterations);
      EXPECT_LT((on_device[p].twist - on_cpu[p].twist).cwiseAbs().maxCoeff(), 1e-5) << on_cpu[p].twist.transpose();
      EXPECT_NEAR(on_device[p].cost, on_cpu[p].cost, 1e-4 * std::fabs(on_cpu[p].cost));
    }
    EXPECT_THROW(refitPairsFromTheBetterMotion(*gpu, moved, {{1, 1}}, {0}, own, 2, true, config), InputError);
  }

  // Remap: labels 0 and 1 merge, label 2 goes to the outlier label, the others shift down.
  std::vector<int> target(std::size_t(n) + 1);
  const int new_count = n - 1;  // n - 2 motion labels + outlier
  target[0] = 0;
  target[1] = 0;
  target[2] = new_count - 1;
  for (int i = 3; i < n; ++i) target[std::size_t(i)] = i - 2;
  target[std::size_t(n)] = new_count - 1;
  for (SolveBackend* b : {cpu.get(), gpu.get()}) b->remap(target, new_count);
  ASSERT_EQ(gpu->labelCount(), new_count);
  EXPECT_LE(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 1e-3) << "after a remap";

  // Cut label 0 across the x axis through its centroid: the same pixels move, the trial's cost model agrees,
  // and the labels change only when the cut is applied.
  const LabelMoments m0 = gpu->ownedMoments()[0];
  ASSERT_GT(m0.count, 10);
  const LabelCut cut{0, m0.sum / m0.count, Eigen::Vector3d::UnitX()};
  std::vector<Vector6d> trial_twists(twists.begin(), twists.begin() + (new_count - 1));
  trial_twists.push_back(trial_twists[0]);
  const SoftLabels before_trial = gpu->downloadLabels();
  const CutTrial ta = cpu->trialCuts({cut}, trial_twists, true, config);
  const CutTrial tb = gpu->trialCuts({cut}, trial_twists, true, config);
  EXPECT_NEAR(ta.moved[0], tb.moved[0], 2.0);
  EXPECT_GT(tb.moved[0], 0);
  ASSERT_EQ(tb.model.curvature.size(), std::size_t(new_count));
  for (int i = 0; i < new_count; ++i)
    expectRelativelyClose(ta.model.curvature[std::size_t(i)].reshaped(), tb.model.curvature[std::size_t(i)].reshaped(),
                          1e-3, "trial curvature of label " + std::to_string(i));
  EXPECT_EQ(gpu->labelCount(), new_count);
  EXPECT_EQ(maxAbsDifference(before_trial, gpu->downloadLabels()), 0.0) << "a trial changed the labels";

  // A cut by the data (label 0's pixels that pay more than a threshold under label 1's motion, so that many do): the
  // data costs are the label step's on both, so the same pixels move.
  {
    const std::vector<Vector6d> current(trial_twists.begin(), trial_twists.end() - 1);  // the labels before the cut
    const LabelCostModel own = cpu->costModel(current, true, config);
    LabelCut by_cost;
    by_cost.parent = 0;
    by_cost.judged_at = trial_twists[1];
    by_cost.cost_above = own.cost[0] / std::max(1.0, own.pixels[0]);
    const CutTrial ca = cpu->trialCuts({by_cost}, trial_twists, true, config);
    const CutTrial cb = gpu->trialCuts({by_cost}, trial_twists, true, config);
    EXPECT_GT(cb.moved[0], 10);
    EXPECT_LT(cb.moved[0], m0.count);
    EXPECT_NEAR(ca.moved[0], cb.moved[0], 2.0);
    for (int i = 0; i < new_count; ++i)
      expectRelativelyClose(ca.model.curvature[std::size_t(i)].reshaped(),
                            cb.model.curvature[std::size_t(i)].reshaped(), 1e-3,
                            "cut by the data: trial curvature of label " + std::to_string(i));
    EXPECT_EQ(maxAbsDifference(before_trial, gpu->downloadLabels()), 0.0) << "a trial by the data changed the labels";
  }
  for (SolveBackend* b : {cpu.get(), gpu.get()}) b->applyCuts({cut}, true, config);
  ASSERT_EQ(gpu->labelCount(), new_count + 1);
  EXPECT_LE(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 1e-3) << "after a cut";

  // The final step: labels carried to level 0 and a label step there from a fresh dual.
  std::vector<Vector6d> final_twists(twists.begin(), twists.begin() + (new_count - 1));
  final_twists.push_back(final_twists[0]);
  for (SolveBackend* b : {cpu.get(), gpu.get()}) {
    b->moveLabels(0);
    b->updateOcclusion(final_twists, config);
  }
  EXPECT_LE(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 1e-3) << "carried to level 0";
  const LabelStepStats fa = cpu->labelStep(final_twists, true, 40, 0.0, config);
  const LabelStepStats fb = gpu->labelStep(final_twists, true, 40, 0.0, config);
  EXPECT_NEAR(fa.energy, fb.energy, 1e-4 * std::fabs(fa.energy));
  EXPECT_LE(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 2e-3) << "final label step";

  // Outputs at level 0 from the labels at the label level (carried up first), with occlusions.
  for (SolveBackend* b : {cpu.get(), gpu.get()}) b->moveLabels(label_level);
  Result ra, rb;
  cpu->outputs(final_twists, config, OutputSelection(), ra);
  gpu->outputs(final_twists, config, OutputSelection(), rb);
  expectSameOutputs(ra, rb);
}

TEST(CudaSolveBackend, StagesMatchCpuAt317x239) {
  SKIP_WITHOUT_GPU();
  compareStages(317, 239, 0);
}

TEST(CudaSolveBackend, StagesMatchCpuAt160x120Variant2) {
  SKIP_WITHOUT_GPU();
  compareStages(160, 120, 2);
}

TEST(CudaSolveBackend, StagesMatchCpuAt64x57) {
  SKIP_WITHOUT_GPU();
  compareStages(64, 57, 1);
}

TEST(CudaSolveBackend, StagesWithCarriedLabelsMatchCpuAt317x239) {
  SKIP_WITHOUT_GPU();
  compareStages(317, 239, 0, 3);
}

TEST(CudaSolveBackend, StagesWithCarriedLabelsMatchCpuAt64x57) {
  SKIP_WITHOUT_GPU();
  compareStages(64, 57, 1, 2);
}

TEST(CudaSolveBackend, RejectsInconsistentCalls) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(64, 48, 0);
  Config config;
  auto gpu = makeCudaSolveBackend();
  gpu->buildPyramids(s.pair.frame1, s.pair.frame2, s.pair.intrinsics, s.p1.size(), config);
  gpu->initialiseLabels(1, assignToNearestCentre(s.p1[1].points, s.centres), int(s.centres.size()));
  const int n = gpu->labelCount() - 1;
  EXPECT_THROW(gpu->initialiseLabels(1, ImageI32(3, 3, 1, 0), 2), InputError);  // wrong size
  ImageI32 beyond(s.p1[1].points.width, s.p1[1].points.height, 1, 0);
  beyond.data[5] = n;
  EXPECT_THROW(gpu->initialiseLabels(1, beyond, n), InputError);  // a label >= motion_labels
  EXPECT_THROW(gpu->labelStep(std::vector<Vector6d>(std::size_t(n) + 1), false, 5, 0.0, config), InputError);
  EXPECT_THROW(gpu->remap(std::vector<int>(std::size_t(n) + 1, 0), n + 1), InputError);  // outlier not last
  EXPECT_THROW(gpu->applyCuts({LabelCut{n, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX()}}, true, Config()),
               InputError);
  EXPECT_THROW(gpu->moveLabels(s.p1.size()), InputError);
}

// The solver's device buffers are reused across pairs of other sizes and label counts: a pair solved after
// others gives exactly the result of a fresh solver.
TEST(CudaSolveBackend, WorkspaceReuseGivesTheFreshResult) {
  SKIP_WITHOUT_GPU();
  Config config;
  config.backend = Backend::Cuda;
  SyntheticSceneOptions a_options, b_options;
  a_options.width = 160;
  a_options.height = 120;
  a_options.variant = 1;
  b_options.width = 320;
  b_options.height = 240;
  b_options.variant = 2;
  const SyntheticPair a = renderSyntheticPair(a_options), b = renderSyntheticPair(b_options);
  Solver fresh(config), reused(config);
  const Result first = fresh.solve(a.frame1, a.frame2, a.intrinsics);
  reused.solve(b.frame1, b.frame2, b.intrinsics);
  reused.solve(a.frame1, a.frame2, a.intrinsics);
  const Result again = reused.solve(a.frame1, a.frame2, a.intrinsics);
  ASSERT_EQ(first.segments.size(), again.segments.size());
  EXPECT_EQ(maxAbsDifference(first.soft_labels, again.soft_labels), 0.0);
  for (std::size_t i = 0; i < first.segments.size(); ++i)
    EXPECT_EQ((first.segments[i].twist - again.segments[i].twist).norm(), 0.0) << "segment " << i;
}

// Solver::recycle: the next solve fills its output images into the recycled result's memory (no fresh allocation,
// no page faults) and gives the same result bit for bit.
TEST(CudaSolveBackend, RecycledResultMemoryIsReused) {
  SKIP_WITHOUT_GPU();
  Config config;
  config.backend = Backend::Cuda;
  SyntheticSceneOptions options;
  options.width = 160;
  options.height = 120;
  const SyntheticPair pair = renderSyntheticPair(options);
  Solver plain(config), recycling(config);
  const Result expected = plain.solve(pair.frame1, pair.frame2, pair.intrinsics);
  Result first = recycling.solve(pair.frame1, pair.frame2, pair.intrinsics);
  const float* scene = first.scene_flow.data.data();
  const float* soft = first.soft_labels.data.data();
  const int* ids = first.labels.data.data();
  recycling.recycle(std::move(first));
  const Result second = recycling.solve(pair.frame1, pair.frame2, pair.intrinsics);
  EXPECT_EQ(second.scene_flow.data.data(), scene);
  EXPECT_EQ(second.soft_labels.data.data(), soft);
  EXPECT_EQ(second.labels.data.data(), ids);
  test::expectSameOutputImages(second, expected);
}

// Config::cuda_device: a device that does not exist is named in the error (cuda), or sends auto to the CPU with
// the reason in the note; device 0 is used when asked for.
TEST(CudaSolveBackend, CudaDeviceSelection) {
  SKIP_WITHOUT_GPU();
  const int missing = 63;  // Config's largest; no test machine has 64 GPUs
  std::string why;
  EXPECT_FALSE(cudaBackendAvailable(&why, missing));
  EXPECT_NE(why.find("CUDA device 63 requested"), std::string::npos) << why;
  try {
    makeSolveBackend(Backend::Cuda, nullptr, missing);
    ADD_FAILURE() << "a missing CUDA device was accepted";
  } catch (const BackendError& e) {
    EXPECT_NE(std::string(e.what()).find("CUDA device 63"), std::string::npos) << e.what();
  }
  std::string note;
  EXPECT_EQ(makeSolveBackend(Backend::Auto, &note, missing)->kind(), Backend::Cpu);
  EXPECT_NE(note.find("CUDA device 63"), std::string::npos) << note;
  Config config;
  config.backend = Backend::Cuda;
  config.cuda_device = 0;
  SyntheticSceneOptions options;
  options.width = 160;
  options.height = 120;
  const SyntheticPair pair = renderSyntheticPair(options);
  const Result r = Solver(config).solve(pair.frame1, pair.frame2, pair.intrinsics);
  EXPECT_EQ(r.backend_kind, Backend::Cuda);
  EXPECT_NE(r.backend_note.find("device 0"), std::string::npos) << r.backend_note;
}

// Two cameras, one GPU: two Solvers, each with its own stream, solving in two threads at once give what each gives
// alone, bit for bit (nothing shared between solvers; the sums run in a fixed order).
TEST(CudaSolveBackend, TwoSolversInTwoThreadsMatchTheirSolosBitForBit) {
  SKIP_WITHOUT_GPU();
  Config config;
  config.backend = Backend::Cuda;
  SyntheticSceneOptions a_options, b_options;
  a_options.variant = 0;
  b_options.variant = 2;
  b_options.width = 160;
  b_options.height = 120;
  const SyntheticPair a = renderSyntheticPair(a_options), b = renderSyntheticPair(b_options);
  const Result solo_a = Solver(config).solve(a.frame1, a.frame2, a.intrinsics);
  const Result solo_b = Solver(config).solve(b.frame1, b.frame2, b.intrinsics);
  Solver solver_a(config), solver_b(config);
  constexpr int kRounds = 4;
  std::vector<Result> results_a(kRounds), results_b(kRounds);
  std::string error_a, error_b;
  auto run = [](Solver& solver, const SyntheticPair& pair, std::vector<Result>& out, std::string& error) {
    try {
      for (Result& r : out) r = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
    } catch (const std::exception& e) {
      error = e.what();
    }
  };
  std::thread thread_a(run, std::ref(solver_a), std::cref(a), std::ref(results_a), std::ref(error_a));
  std::thread thread_b(run, std::ref(solver_b), std::cref(b), std::ref(results_b), std::ref(error_b));
  thread_a.join();
  thread_b.join();
  ASSERT_TRUE(error_a.empty()) << error_a;
  ASSERT_TRUE(error_b.empty()) << error_b;
  for (int k = 0; k < kRounds; ++k) {
    for (const auto& [solo, concurrent] : {std::pair<const Result*, const Result*>{&solo_a, &results_a[k]},
                                           std::pair<const Result*, const Result*>{&solo_b, &results_b[k]}}) {
      ASSERT_EQ(solo->segments.size(), concurrent->segments.size()) << "round " << k;
      EXPECT_EQ(maxAbsDifference(solo->soft_labels, concurrent->soft_labels), 0.0) << "round " << k;
      for (std::size_t i = 0; i < solo->segments.size(); ++i)
        EXPECT_EQ((solo->segments[i].twist - concurrent->segments[i].twist).norm(), 0.0) << "round " << k;
    }
  }
}

// K-means on the device against kmeansPoints on the host, at every level of the synthetic scenes (40x30 to 640x480
// points) with the default and other parameters: the same number of centres, each within 1e-5 m of the host's (the
// clusters' double sums run in another order: a mean may differ by an ulp of a float; in practice they agree bit for
// bit, which the test reports). Fewer distinct points than k give fewer centres, and no valid point none.
TEST(CudaSolveBackend, KMeansCentresMatchTheHost) {
  SKIP_WITHOUT_GPU();
  Config config;
  auto cpu = makeCpuSolveBackend();
  auto gpu = makeCudaSolveBackend();
  int compared = 0, identical = 0;
  auto compare = [&](int level, int k, int iterations, double tolerance, unsigned seed, const std::string& what) {
    const std::vector<Eigen::Vector3f> a = cpu->kmeansCentres(level, k, iterations, tolerance, seed);
    const std::vector<Eigen::Vector3f> b = gpu->kmeansCentres(level, k, iterations, tolerance, seed);
    ASSERT_EQ(a.size(), b.size()) << what;
    for (std::size_t c = 0; c < a.size(); ++c) {
      EXPECT_LE((a[c] - b[c]).cwiseAbs().maxCoeff(), 1e-5f) << what << ", centre " << c;
      identical += a[c] == b[c] ? 1 : 0;
      ++compared;
    }
  };
  for (const auto& [width, height, variant] :
       {std::tuple{320, 240, 0}, std::tuple{320, 240, 1}, std::tuple{317, 239, 2}, std::tuple{640, 480, 0}}) {
    const int levels = buildBothPyramids(*cpu, *gpu, width, height, variant, config);
    for (int level = 0; level < levels; ++level) {
      const std::string what = std::to_string(width) + "x" + std::to_string(height) + " variant " +
                               std::to_string(variant) + " level " + std::to_string(level);
      compare(level, config.initial_labels, config.kmeans_max_iterations, config.kmeans_tolerance, config.seed, what);
      compare(level, 64, 30, 0.0, 12345u, what + ", 64 centres, 30 iterations");
      compare(level, 3, 0, 0.0, 9u, what + ", seeding only");
    }
  }
  std::printf("K-means: %d of %d centres bit-identical to the host's\n", identical, compared);
}

// A warm start's K-means of the pixels no carried segment covers (initialiseLabelsWithUncoveredClusters) on the device
// against the host's default: the same clusters kept and the same initial labels, with carried labels on part of the
// level (two carried labels, first_new 2), with none (first_new 0) and covering every pixel (no cluster), at two sizes
// and several cluster counts; hard labels outside [-1, first_new) refused by both. The labels are compared exactly:
// a centre an ulp off the host's (cuda/kmeans.cu says when) would move a pixel only on a tie, and
// KMeansCentresMatchTheHost finds every centre bit-identical on these scenes.
TEST(CudaSolveBackend, UncoveredClustersMatchTheHost) {
  SKIP_WITHOUT_GPU();
  Config config;
  auto cpu = makeCpuSolveBackend();
  auto gpu = makeCudaSolveBackend();
  for (const auto& [width, height, variant] : {std::tuple{320, 240, 2}, std::tuple{317, 239, 1}}) {
    buildBothPyramids(*cpu, *gpu, width, height, variant, config);
    const int level = 1;
    const ImageF& points = cpu->framePoints(level);
    for (const bool carried : {true, false}) {
      // Carried: label 0 on the left third, 1 on the middle third, the right third uncovered.
      ImageI32 hard(points.width, points.height, 1, -1);
      if (carried)
        for (int y = 0; y < hard.height; ++y)
          for (int x = 0; x < 2 * hard.width / 3; ++x) hard(x, y) = x < hard.width / 3 ? 0 : 1;
      const int first_new = carried ? 2 : 0;
      for (const int clusters : {1, 3, 8}) {
        const std::string what = std::to_string(width) + "x" + std::to_string(height) + (carried ? " carried" : "") +
                                 ", " + std::to_string(clusters) + " clusters";
        const int a = cpu->initialiseLabelsWithUncoveredClusters(level, hard, first_new, clusters, config);
        const int b = gpu->initialiseLabelsWithUncoveredClusters(level, hard, first_new, clusters, config);
        EXPECT_EQ(a, b) << what;
        EXPECT_GE(a, 1) << what;
        EXPECT_EQ(cpu->labelCount(), first_new + a + 1) << what;
        EXPECT_EQ(gpu->labelCount(), first_new + b + 1) << what;
        EXPECT_EQ(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 0.0) << what;
      }
    }
    ImageI32 covered(points.width, points.height, 1, 0);  // every pixel carried: nothing to cluster
    for (int y = 0; y < covered.height; ++y)
      for (int x = covered.width / 2; x < covered.width; ++x) covered(x, y) = 1;
    EXPECT_EQ(cpu->initialiseLabelsWithUncoveredClusters(level, covered, 2, 3, config), 0);
    EXPECT_EQ(gpu->initialiseLabelsWithUncoveredClusters(level, covered, 2, 3, config), 0);
    EXPECT_EQ(gpu->labelCount(), 3);
    EXPECT_EQ(maxAbsDifference(cpu->downloadLabels(), gpu->downloadLabels()), 0.0) << "every pixel carried";
    covered(0, 0) = 2;  // not a carried label when the new ones start at 2
    EXPECT_THROW(cpu->initialiseLabelsWithUncoveredClusters(level, covered, 2, 3, config), InputError);
    EXPECT_THROW(gpu->initialiseLabelsWithUncoveredClusters(level, covered, 2, 3, config), InputError);
  }
}

// Small inputs (the sanitizers' case): a 64x48 scene at every level, three valid pixels for 20 centres (three centres),
// and none valid (no centre).
TEST(CudaSolveBackend, KMeansCentresOfFewOrNoValidPoints) {
  SKIP_WITHOUT_GPU();
  Config config;
  auto cpu = makeCpuSolveBackend();
  auto gpu = makeCudaSolveBackend();
  auto compare = [&](int level, int k, int iterations, double tolerance, unsigned seed, const std::string& what) {
    const std::vector<Eigen::Vector3f> a = cpu->kmeansCentres(level, k, iterations, tolerance, seed);
    const std::vector<Eigen::Vector3f> b = gpu->kmeansCentres(level, k, iterations, tolerance, seed);
    ASSERT_EQ(a.size(), b.size()) << what;
    for (std::size_t c = 0; c < a.size(); ++c)
      EXPECT_LE((a[c] - b[c]).cwiseAbs().maxCoeff(), 1e-5f) << what << ", centre " << c;
  };
  SyntheticSceneOptions options;
  options.width = 64;
  options.height = 48;
  SyntheticPair pair = renderSyntheticPair(options);
  const int levels = pyramidLevelCount(64, 48, config.coarsest_min_width);
  for (SolveBackend* b : {cpu.get(), gpu.get()})
    b->buildPyramids(pair.frame1, pair.frame2, pair.intrinsics, levels, config);
  for (int level = 0; level < levels; ++level) compare(level, 20, 10, 0.01, 7u, "64x48 level " + std::to_string(level));

  // Three valid pixels (depth elsewhere outside [min_depth, max_depth]): three centres out of 20; then none valid.
  for (float& z : pair.frame1.depth.data) z = 0.f;
  pair.frame1.depth(5, 5) = 1.0f;
  pair.frame1.depth(40, 20) = 1.5f;
  pair.frame1.depth(60, 47) = 2.0f;
  for (SolveBackend* b : {cpu.get(), gpu.get()}) b->buildPyramids(pair.frame1, pair.frame2, pair.intrinsics, 1, config);
  compare(0, 20, 10, 0.01, 7u, "three valid points");
  EXPECT_EQ(gpu->kmeansCentres(0, 20, 10, 0.01, 7u).size(), 3u);
  for (float& z : pair.frame1.depth.data) z = 0.f;
  for (SolveBackend* b : {cpu.get(), gpu.get()}) b->buildPyramids(pair.frame1, pair.frame2, pair.intrinsics, 1, config);
  EXPECT_TRUE(gpu->kmeansCentres(0, 20, 10, 0.01, 7u).empty());
  EXPECT_TRUE(cpu->kmeansCentres(0, 20, 10, 0.01, 7u).empty());
}

// The soft labels and the scene flow not selected: not downloaded, 0x0 in the result; every other output and the next
// pair's warm start (from a result without them) are the full selection's, bit for bit.
TEST(CudaSolveBackend, OutputsNotSelectedAreLeftOutAndTheRestIsTheSame) {
  SKIP_WITHOUT_GPU();
  Config config;
  config.backend = Backend::Cuda;
  SyntheticSceneOptions options;
  options.variant = 1;
  const SyntheticPair pair = renderSyntheticPair(options);
  Solver all(config), some(config);
  OutputSelection none;
  none.soft_labels = none.scene_flow = false;
  some.setOutputs(none);
  const Result a = all.solve(pair.frame1, pair.frame2, pair.intrinsics);
  const Result b = some.solve(pair.frame1, pair.frame2, pair.intrinsics);
  EXPECT_EQ(b.soft_labels.count, 0);
  EXPECT_TRUE(b.soft_labels.data.empty());
  EXPECT_EQ(b.scene_flow.width, 0);
  EXPECT_TRUE(b.scene_flow.data.empty());
  EXPECT_FALSE(a.soft_labels.data.empty());
  auto without = [](Result r) {
    r.soft_labels = SoftLabels();
    r.scene_flow = ImageF();
    return r;
  };
  EXPECT_EQ(firstDifference(without(a), b), "");
  // The warm start of the next pair (the same frames again) from each result.
  const Result wa = all.solve(pair.frame1, pair.frame2, pair.intrinsics, a);
  const Result wb = some.solve(pair.frame1, pair.frame2, pair.intrinsics, b);
  EXPECT_EQ(wb.start, StartKind::Warm) << wb.start_note;
  EXPECT_EQ(firstDifference(without(wa), wb), "");
}

// Grow-only buffers: once a solver has seen pairs of a size and label count (cold and warm), solving them again
// allocates no device or page-locked memory.
TEST(CudaSolveBackend, NoAllocationAfterTheFirstPairsOfASize) {
  SKIP_WITHOUT_GPU();
  Config config;
  config.backend = Backend::Cuda;
  SyntheticSceneOptions a_options, b_options;
  a_options.variant = 1;
  b_options.variant = 2;
  const SyntheticPair a = renderSyntheticPair(a_options), b = renderSyntheticPair(b_options);
  Solver solver(config);
  auto solveAll = [&] {
    const Result first = solver.solve(a.frame1, a.frame2, a.intrinsics);
    solver.solve(b.frame1, b.frame2, b.intrinsics);
    solver.solve(a.frame1, a.frame2, a.intrinsics, first);  // the warm path
  };
  solveAll();
  const CudaCounters before = cudaCounters();
  solveAll();
  const CudaCounters after = cudaCounters();
  EXPECT_EQ(after.device_allocations, before.device_allocations);
  EXPECT_EQ(after.pinned_allocations, before.pinned_allocations);
  EXPECT_GT(after.kernel_launches, before.kernel_launches);
  std::printf("kernel launches per solve: %.0f\n", double(after.kernel_launches - before.kernel_launches) / 3.0);
}

// The label step's graphs (its unchecked iterations) are kept per launch configuration: a pair solved again, cold and
// warm, captures none, and gives the same result bit for bit.
TEST(CudaSolveBackend, LabelStepGraphsAreReusedWhenTheConfigurationsComeBack) {
  SKIP_WITHOUT_GPU();
  Config config;
  config.backend = Backend::Cuda;
  SyntheticSceneOptions options;
  options.variant = 2;
  const SyntheticPair pair = renderSyntheticPair(options);
  Solver solver(config);
  const CudaCounters start = cudaCounters();
  const Result cold = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
  const Result warm = solver.solve(pair.frame1, pair.frame2, pair.intrinsics, cold);
  const CudaCounters first = cudaCounters();
  EXPECT_GT(first.graph_instantiations, start.graph_instantiations);
  const Result cold_again = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
  const Result warm_again = solver.solve(pair.frame1, pair.frame2, pair.intrinsics, cold_again);
  EXPECT_EQ(cudaCounters().graph_instantiations, first.graph_instantiations);
  std::printf("label-step graphs instantiated by a cold and a warm solve: %llu\n",
              static_cast<unsigned long long>(first.graph_instantiations - start.graph_instantiations));
  EXPECT_EQ(cold_again.soft_labels.data, cold.soft_labels.data);
  EXPECT_EQ(warm_again.soft_labels.data, warm.soft_labels.data);
  EXPECT_EQ(warm_again.labels.data, warm.labels.data);
}

// Stream mode's carry on the device (cuda/warm_start.cu) against the host's (warm_start.cpp): the same carried ids and
// dormant regions and the same hard labels at every label level, bit for bit (the device's majority up to 8 x 8 input
// pixels per level pixel, the host's beyond).
TEST(CudaSolveBackend, CarriedSegmentsMatchTheHostBitForBit) {
  SKIP_WITHOUT_GPU();
  SyntheticSceneOptions options;
  options.variant = 2;
  const SyntheticPair pair = renderSyntheticPair(options);
  Config config;
  config.backend = Backend::Cpu;
  Result previous = Solver(config).solve(pair.frame1, pair.frame2, pair.intrinsics);
  ASSERT_GE(previous.segments.size(), 2u);
  // Dormant regions: every segment's pixels under another id, so that the second carry differs from the first.
  previous.dormant_ids = {{100, 1}};
  previous.dormant_regions = previous.labels;
  for (int& id : previous.dormant_regions.data)
    if (id > 0) id += 99;
  // The next pair starts at the previous pair's frame 2.
  const int levels = pyramidLevelCount(pair.frame2.width(), pair.frame2.height(), config.coarsest_min_width);
  ASSERT_GE(levels, 5);
  std::unique_ptr<SolveBackend> cpu = makeCpuSolveBackend(), gpu = makeCudaSolveBackend();
  cpu->buildPyramids(pair.frame2, pair.frame1, pair.intrinsics, levels, config);
  gpu->buildPyramids(pair.frame2, pair.frame1, pair.intrinsics, levels, config);
  for (int level = -1; level < levels; ++level) {
    const CarriedSegments a = cpu->carrySegments(previous, pair.frame2.depth, level, config);
    const CarriedSegments b = gpu->carrySegments(previous, pair.frame2.depth, level, config);
    const std::string what = "label level " + std::to_string(level);
    EXPECT_EQ(a.ids.data, b.ids.data) << what;
    EXPECT_EQ(a.dormant.data, b.dormant.data) << what;
    EXPECT_EQ(a.labels.hard.width, b.labels.hard.width) << what;
    EXPECT_EQ(a.labels.hard.data, b.labels.hard.data) << what;
    EXPECT_EQ(a.labels.ids, b.labels.ids) << what;
    EXPECT_EQ(a.labels.covered, b.labels.covered) << what;
    EXPECT_EQ(a.labels.valid, b.labels.valid) << what;
    if (level == 1) {  // the carry is not empty: most of frame 2 continues the previous segments
      const long carried = std::count_if(a.ids.data.begin(), a.ids.data.end(), [](int id) { return id > 0; });
      EXPECT_GT(carried, long(a.ids.data.size() / 2));
      EXPECT_GT(a.labels.coverage(), 0.5);
      EXPECT_GT(std::count_if(a.dormant.data.begin(), a.dormant.data.end(), [](int id) { return id > 99; }), 0);
    }
  }
  // Sizes that do not fit are refused with the sizes named.
  Result small = previous;
  small.width = 10;
  EXPECT_THROW(gpu->carrySegments(small, pair.frame2.depth, 1, config), InputError);
}

// A stream pair's carry reads the previous result's ids, flow and moved depth where the backend left them (its latest
// outputs, Result::device_outputs, in the memory the solve filled) and uploads only a table of the ids and the dormant
// regions; a copy of that result, or one whose images a later solve replaced on the device, is uploaded whole. All give
// the same result bit for bit.
TEST(CudaSolveBackend, AStreamPairCarriesThePreviousOutputsLeftOnTheDevice) {
  SKIP_WITHOUT_GPU();
  SyntheticSceneOptions options;
  options.variant = 2;
  const SyntheticPair pair = renderSyntheticPair(options);
  Config config;
  config.backend = Backend::Cuda;
  Solver solver(config);
  // The first pair, with ids that are not the label indices (as a stream's) and dormant regions (always uploaded).
  auto firstPair = [&] {
    Result r = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
    r.dormant_ids = {{100, 1}};
    r.dormant_regions = r.labels;
    for (int& id : r.dormant_regions.data)
      if (id > 0) id += 99;
    std::vector<int> new_id(r.segments.size() + 1, 0);
    for (std::size_t i = 0; i < r.segments.size(); ++i) new_id[i + 1] = r.segments[i].id = int(7 + 3 * i);
    for (int& label : r.labels.data) label = new_id[std::size_t(label)];
    r.next_id = int(7 + 3 * r.segments.size());
    return r;  // moved out: the images keep their memory
  };
  const std::size_t pixels = std::size_t(pair.frame1.width()) * std::size_t(pair.frame1.height());
  const std::size_t whole = 5 * pixels * sizeof(float);  // ids, flow, moved depth, dormant regions
  auto uploadedBy = [&](const Result& previous, Result& out) {
    const std::uint64_t before = cudaCounters().carry_bytes_uploaded;
    out = solver.solve(pair.frame2, pair.frame1, pair.intrinsics, previous);
    return cudaCounters().carry_bytes_uploaded - before;
  };

  Result first = firstPair();
  ASSERT_NE(first.device_outputs, 0u);
  ASSERT_GE(first.segments.size(), 2u);
  const Result copy = first;  // the serial, not the memory
  Result from_copy, on_device, stale;
  EXPECT_EQ(uploadedBy(copy, from_copy), whole);
  first = firstPair();
  EXPECT_EQ(uploadedBy(first, on_device), (first.segments.size() + 1 + pixels) * sizeof(int));
  EXPECT_EQ(uploadedBy(first, stale), whole);  // on_device's solve replaced first's images on the device
  EXPECT_EQ(on_device.start, StartKind::Warm);
  for (const Result* other : {&from_copy, &stale}) {
    EXPECT_EQ(firstDifference(on_device, *other), "");
    EXPECT_EQ(on_device.dormant_regions.data, other->dormant_regions.data);
    EXPECT_EQ(on_device.dormant_ids, other->dormant_ids);
    EXPECT_EQ(on_device.merged_ids, other->merged_ids);
    EXPECT_EQ(on_device.ended_ids, other->ended_ids);
    EXPECT_EQ(on_device.revived_ids, other->revived_ids);
    EXPECT_EQ(on_device.next_id, other->next_id);
    EXPECT_EQ(on_device.world.ids, other->world.ids);
  }
  // The ids continue the renamed ones (the carry read them through the table), and the dormant id is remembered.
  int continued = 0;
  for (const Segment& s : on_device.segments)
    for (const Segment& p : first.segments) continued += s.id == p.id ? 1 : 0;
  EXPECT_GE(continued, 2);
  EXPECT_FALSE(on_device.dormant_regions.data.empty());
}

// The same at an awkward size with a made-up previous result: ids <= 0, flow off the image, NaN and infinite, moved
// depths of 0, NaN, infinity and below zero, points that land on one pixel at the same depth (a tie: the first in
// raster order wins) and frame 1's depth outside [min_depth, max_depth], NaN or 0.
TEST(CudaSolveBackend, CarriedSegmentsOfAwkwardInputMatchTheHostBitForBit) {
  SKIP_WITHOUT_GPU();
  const int W = 317, H = 239;
  Config config;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  RgbdFrame frame1, frame2;
  frame1.intensity = ImageF(W, H, 1);
  frame1.depth = ImageF(W, H, 1);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      frame1.intensity(x, y) = unit(rng);
      const float r = unit(rng);
      frame1.depth(x, y) = r < 0.05f   ? 0.f
                           : r < 0.08f ? std::numeric_limits<float>::quiet_NaN()
                           : r < 0.1f  ? float(config.max_depth) + 1.f
                                       : 1.f + 0.02f * float((x / 40 + y / 30) % 3);  // steps of 2 cm
    }
  frame2 = frame1;
  Result previous;
  previous.width = W;
  previous.height = H;
  previous.labels = ImageI32(W, H, 1);
  previous.optical_flow = ImageF(W, H, 2);
  previous.moved_depth = ImageF(W, H, 1);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float r = unit(rng);
      previous.labels(x, y) = r < 0.05f ? -3 : r < 0.1f ? 0 : 1 + (x / 50) + 7 * (y / 60);
      float fu = 1.5f * unit(rng) - 0.5f, fv = 1.5f * unit(rng) - 0.5f;
      if (x % 7 == 0) fu = 0.5f;               // exactly half a pixel: rounds away from zero
      if (x % 11 == 0) fu = -float(x) - 0.7f;  // off the left border
      if (y % 13 == 0) fv = nan;
      if (y % 17 == 0) fu = inf;
      const float m = unit(rng);
      float moved = m < 0.03f   ? 0.f
                    : m < 0.05f ? nan
                    : m < 0.07f ? inf
                    : m < 0.09f ? -1.f
                                : frame1.depth(std::min(W - 1, x + 1), y) + 0.03f * (m - 0.5f);
      if (y % 4 == 0 && x % 5 < 2) {  // pixels 5k and 5k + 1 land on 5k at the same depth: a tie
        fu = x % 5 == 0 ? 0.f : -1.f;
        fv = 0.f;
        moved = frame1.depth(x - x % 5, y);
        if (x % 5 == 1) previous.labels(x, y) = 99;  // the loser of the tie, so that a wrong winner shows
      }
      previous.optical_flow(x, y, 0) = fu;
      previous.optical_flow(x, y, 1) = fv;
      previous.moved_depth(x, y) = moved;
    }
  previous.dormant_ids = {{500, 2}};
  previous.dormant_regions = ImageI32(W, H, 1);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) previous.dormant_regions(x, y) = (x + y) % 9 == 0 ? 500 : (x * y) % 5 == 0 ? -1 : 0;
  const int levels = pyramidLevelCount(W, H, config.coarsest_min_width);
  std::unique_ptr<SolveBackend> cpu = makeCpuSolveBackend(), gpu = makeCudaSolveBackend();
  const Intrinsics K{300.0, 300.0, 158.0, 119.0};
  cpu->buildPyramids(frame1, frame2, K, levels, config);
  gpu->buildPyramids(frame1, frame2, K, levels, config);
  long carried_pixels = 0;
  for (int level = -1; level < levels; ++level) {
    const CarriedSegments a = cpu->carrySegments(previous, frame1.depth, level, config);
    const CarriedSegments b = gpu->carrySegments(previous, frame1.depth, level, config);
    const std::string what = "label level " + std::to_string(level);
    EXPECT_EQ(a.ids.data, b.ids.data) << what;
    EXPECT_EQ(a.dormant.data, b.dormant.data) << what;
    EXPECT_EQ(a.labels.hard.data, b.labels.hard.data) << what;
    EXPECT_EQ(a.labels.ids, b.labels.ids) << what;
    EXPECT_EQ(a.labels.covered, b.labels.covered) << what;
    EXPECT_EQ(a.labels.valid, b.labels.valid) << what;
    carried_pixels = std::count_if(a.ids.data.begin(), a.ids.data.end(), [](int id) { return id > 0; });
  }
  EXPECT_GT(carried_pixels, long(W) * H / 4);                                            // the test carries something
  EXPECT_THROW(gpu->carrySegments(previous, frame1.depth, levels, config), InputError);  // a level it lacks
}

// Whole solves on both backends: the same number of segments and EPE within 0.01 px on the synthetic scenes.
TEST(CudaSolveBackend, SolverMatchesCpuOnSyntheticScenes) {
  SKIP_WITHOUT_GPU();
  for (int variant = 0; variant < 3; ++variant) {
    SyntheticSceneOptions options;
    options.variant = variant;
    const SyntheticPair pair = renderSyntheticPair(options);
    Config cpu_config, gpu_config;
    cpu_config.backend = Backend::Cpu;
    gpu_config.backend = Backend::Cuda;
    Solver cpu_solver(cpu_config), gpu_solver(gpu_config);
    const Result a = cpu_solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
    const Result b = gpu_solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
    EXPECT_EQ(b.backend_kind, Backend::Cuda);
    const FlowErrors ea = opticalFlowErrors(a.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
    const FlowErrors eb = opticalFlowErrors(b.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
    std::printf("variant %d: segments cpu %zu gpu %zu, EPE cpu %.4f px gpu %.4f px\n", variant, a.segments.size(),
                b.segments.size(), ea.epe, eb.epe);
    EXPECT_EQ(a.segments.size(), b.segments.size()) << "variant " << variant;
    EXPECT_LT(std::abs(ea.epe - eb.epe), 0.01) << "variant " << variant;
    EXPECT_LT(eb.epe, 0.4) << "variant " << variant;
  }
}

// The depth noise model (Config::depth_noise_reference, motion_pixel::depthCauchyScale in both accumulators and both
// data costs): on a pair with Kinect-like noise the GPU gives the CPU's segments and, within the parity tolerance, its
// flow, and the model changes the result on both.
TEST(CudaSolveBackend, SolverMatchesCpuWithTheDepthNoiseModel) {
  SKIP_WITHOUT_GPU();
  SyntheticSceneOptions options;
  options.variant = 0;
  options.addSensorNoise();
  const SyntheticPair pair = renderSyntheticPair(options);
  Config cpu_config, gpu_config;
  cpu_config.backend = Backend::Cpu;
  gpu_config.backend = Backend::Cuda;
  cpu_config.depth_noise_reference = gpu_config.depth_noise_reference = 1.5;
  const Result a = Solver(cpu_config).solve(pair.frame1, pair.frame2, pair.intrinsics);
  const Result b = Solver(gpu_config).solve(pair.frame1, pair.frame2, pair.intrinsics);
  gpu_config.depth_noise_reference = 0.0;
  const Result off = Solver(gpu_config).solve(pair.frame1, pair.frame2, pair.intrinsics);
  const FlowErrors ea = opticalFlowErrors(a.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
  const FlowErrors eb = opticalFlowErrors(b.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
  const FlowErrors eo = opticalFlowErrors(off.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
  std::printf("depth noise model 1.5 m: segments cpu %zu gpu %zu, EPE cpu %.4f px gpu %.4f px (model off: %.4f px)\n",
              a.segments.size(), b.segments.size(), ea.epe, eb.epe, eo.epe);
  EXPECT_EQ(a.segments.size(), b.segments.size());
  EXPECT_LT(std::abs(ea.epe - eb.epe), 0.01);
  EXPECT_LT(eb.epe, eo.epe);
}

}  // namespace
}  // namespace mc_flow

// The static world (static_world.h) on the device: the same segments and, within the parity tolerance, the same
// motion and covariance as the CPU's, chosen the same way; its fit runs on the labels at the processing level.
TEST(CudaSolveBackend, TheStaticWorldMatchesTheCpus) {
  SKIP_WITHOUT_GPU();
  mc_flow::SyntheticSceneOptions so;
  so.variant = 1;
  so.camera_only = true;
  so.camera_only_translation_m = Eigen::Vector3d(0.03, -0.01, 0.02);
  so.camera_only_rotation_deg = Eigen::Vector3d(1.0, -2.5, 0.5);
  const mc_flow::SyntheticPair pair = mc_flow::renderSyntheticPair(so);
  mc_flow::Config config;
  config.threads = 2;
  config.backend = mc_flow::Backend::Cpu;
  mc_flow::Solver cpu(config);
  config.backend = mc_flow::Backend::Cuda;
  mc_flow::Solver cuda(config);
  const Eigen::Matrix4d camera = mc_flow::se3Exp(pair.parts.front().twist).inverse();
  for (const bool prior : {false, true}) {
    const mc_flow::Result a = prior ? cpu.solve(pair.frame1, pair.frame2, pair.intrinsics, nullptr, camera)
                                    : cpu.solve(pair.frame1, pair.frame2, pair.intrinsics);
    const mc_flow::Result b = prior ? cuda.solve(pair.frame1, pair.frame2, pair.intrinsics, nullptr, camera)
                                    : cuda.solve(pair.frame1, pair.frame2, pair.intrinsics);
    ASSERT_TRUE(b.world.found);
    EXPECT_EQ(b.world.chosen_by, a.world.chosen_by);
    EXPECT_EQ(b.world.ids, a.world.ids);
    EXPECT_LT((b.world.twist - a.world.twist).norm(), 1e-4) << a.world.twist.transpose() << "\n"
                                                            << b.world.twist.transpose();
    EXPECT_TRUE(b.world.covariance.isApprox(a.world.covariance, 0.05)) << a.world.covariance << "\n"
                                                                       << b.world.covariance;
  }
}

// The depth order's choices on the device: a stream that remembers a part (in front of the room) as its world leaves it
// for the room ("behind"), as the CPU does, and the room's pieces that join the world are the CPU's.
TEST(CudaSolveBackend, TheWorldBehindARememberedPartMatchesTheCpus) {
  SKIP_WITHOUT_GPU();
  const mc_flow::StreamFrame f0 = mc_flow::test::syntheticStreamFrame(0, 0.0),
                             f1 = mc_flow::test::syntheticStreamFrame(1, 1 / 30.0),
                             f2 = mc_flow::test::syntheticStreamFrame(2, 2 / 30.0);
  mc_flow::Config config;
  config.threads = 2;
  config.backend = mc_flow::Backend::Cpu;
  mc_flow::Solver first(config);
  mc_flow::Result previous = first.solve(f0.frame, f1.frame, f0.K);
  ASSERT_GE(previous.segments.size(), 2u);
  const int room_id = previous.world.ids.front();
  const auto smallest =
      std::min_element(previous.segments.begin(), previous.segments.end(),
                       [](const mc_flow::Segment& a, const mc_flow::Segment& b) { return a.support < b.support; });
  ASSERT_NE(smallest->id, room_id);
  previous.world.ids = {smallest->id};
  config.world_outgrown_ratio = 1e6;  // only the depth order can leave the remembered part
  mc_flow::Solver cpu(config);
  config.backend = mc_flow::Backend::Cuda;
  mc_flow::Solver cuda(config);
  const mc_flow::Result a = cpu.solve(f1.frame, f2.frame, f1.K, previous);
  const mc_flow::Result b = cuda.solve(f1.frame, f2.frame, f1.K, previous);
  EXPECT_EQ(a.world.chosen_by, "behind");
  EXPECT_EQ(b.world.chosen_by, a.world.chosen_by);
  EXPECT_EQ(b.world.ids, a.world.ids);
  EXPECT_NE(std::find(b.world.ids.begin(), b.world.ids.end(), room_id), b.world.ids.end());
}
