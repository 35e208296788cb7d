/**
 * @file label_adaptation.h
 * @brief Label count (section 5), decided on the energy: labels merge when one motion explains both
 * almost as well as two, labels split when two motions explain one much better, each against a label
 * cost (an MDL-style price per motion). Tiny labels go to the outlier label.
 *
 * The decisions use a local quadratic model of each label's data cost around its twist, built in one
 * pass over the pixels (the motion step's normal equations, per label): merging or splitting is then
 * work in the number of labels, not image passes. Derivation: docs/ALGORITHM.md, "Label count".
 */
#pragma once

#include <memory>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

class SolveBackend;

struct AdaptationStats {
  int merged = 0;
  int removed = 0;
  int split = 0;
  int rounds = 0;        ///< mergeWhereOneMotionExplains: rounds that refitted pairs
  int pairs_tested = 0;  ///< mergeWhereOneMotionExplains: pairs refitted on their union
  /// Smallest predicted data-cost increase of a merge that was refused (infinity when none was left)
  /// [normalised Cauchy cost, summed over the label level's pixels].
  double smallest_refused_merge = 0;
};

/// @brief Stream memory of one motion label: whether it descends from a segment of the previous pair, and that
/// segment's motion over the previous interval and its centroid (the previous pair's frame 1) [m, rad]. A label that
/// is not carried (a cold start's, K-means on uncovered pixels, a split-off half) holds no memory.
struct LabelLineage {
  bool carried = false;
  Vector6d previous_twist = Vector6d::Zero();
  Eigen::Vector3d previous_centroid = Eigen::Vector3d::Zero();
};

/// @brief The lineage of a label that keeps `keep` and absorbs `drop`: keep's, or drop's where only drop was carried.
LabelLineage mergedLineage(const LabelLineage& keep, const LabelLineage& drop);

/// @brief Whether two carried labels moved apart in the previous pair: at either one's previous centroid, their two
/// previous motions put the point more than `displacement` [m] apart. False when either is not carried or
/// `displacement` <= 0.
bool movedApartBefore(const LabelLineage& a, const LabelLineage& b, double displacement);

/// @brief Each motion label's data cost near its twist xi_i: E_i(xi_i + d) ~ E_i + 2 g_i^T d + d^T H_i d
/// (Gauss-Newton on the normalised Cauchy cost, the motion step's diagonal blocks).
struct LabelCostModel {
  std::vector<Matrix6d> curvature;  ///< H_i
  std::vector<Vector6d> gradient;   ///< g_i
  std::vector<double> cost;         ///< E_i, the data cost the label pays now (robust cost shared by weight)
  std::vector<double> pixels;       ///< the label's weighted pixel count in the pass [px]
};

/// @brief One rigid motion refitted on the union of a group of motion labels' pixels (refitUnions).
struct UnionFit {
  Vector6d twist = Vector6d::Zero();      ///< the union's motion
  std::vector<double> member_cost;        ///< each member's data cost under `twist` [normalised Cauchy cost]
  double cost = 0;                        ///< their sum
  double pixels = 0;                      ///< the members' weighted pixels [px]
  Matrix6d curvature = Matrix6d::Zero();  ///< the union's Gauss-Newton curvature H at `twist`
  int iterations = 0;                     ///< accepted Gauss-Newton steps
};

/// @brief What a label owns (u_i >= 0.5, valid depth): pixel count, sum of P, sum of P P^T [m, m^2].
struct LabelMoments {
  double count = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
  void add(const Eigen::Vector3d& P) {
    count += 1;
    sum += P;
    outer += P * P.transpose();
  }
  Eigen::Vector3d mean() const { return sum / count; }
  /// Unit direction of the points' largest spread (the covariance's top eigenvector); needs count >= 1.
  Eigen::Vector3d principalAxis() const;
};

/// @brief A cut of label `parent`: its owned pixels (u >= 0.5, valid depth) with (P - centre) . axis > 0 move to a new
/// label (u value carried over, parent set to 0). A cut by the data (`cost_above` > 0) moves instead the owned pixels
/// whose data cost D (eq. 5, computeDataCosts under `judged_at`, with the store's occlusion mask when the call uses
/// it) exceeds `cost_above`.
struct LabelCut {
  int parent = 0;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
  double cost_above = 0;  ///< > 0: a cut by the data [normalised Cauchy cost per pixel]
  Vector6d judged_at = Vector6d::Zero();
};

/// @brief proposeSplits also tries, for each label, the cut by the data of its pixels that pay more than this many
/// times the label's own cost per pixel under its motion: where K-means' labels mixed parts with the room and merged,
/// the parts stand out by their residuals, not by where they are (docs/decisions/0019, chosen there).
inline constexpr double kSplitCostFactor = 5.0;

/// @brief What a set of cuts would do: the pixels each moves, and the cost model with all of them applied.
struct CutTrial {
  std::vector<double> moved;
  LabelCostModel model;
};

/// @brief The label operations the label-count update needs, wherever the labels live (host or device).
/// Motion labels are 0..labelCount()-2, the outlier label is the last plane.
class LabelStore {
 public:
  virtual ~LabelStore() = default;
  /// @brief Label planes, the outlier label included.
  virtual int labelCount() const = 0;
  /// @brief Sum of u_i over the pixels, per motion label.
  virtual std::vector<double> supports() = 0;
  /// @brief New plane j = sum of the old planes i with target[i] == j, added in ascending i. `target` has
  /// one entry per old plane (the outlier included) with values in [0, new_count); the last old plane must
  /// map to new_count - 1 (the outlier stays last). Resets the dual variables when the count changes.
  virtual void remap(const std::vector<int>& target, int new_count) = 0;
  /// @brief Moments of every motion label's owned pixels.
  virtual std::vector<LabelMoments> ownedMoments() = 0;
  /// @brief Without changing the labels: the pixels each cut would move, and the cost model of the labelling
  /// with all cuts applied (cut c as motion label labelCount()-1+c) at `twists` (one per label of that
  /// labelling).
  virtual CutTrial trialCuts(const std::vector<LabelCut>& cuts, const std::vector<Vector6d>& twists, bool use_occlusion,
                             const Config& config) = 0;
  /// @brief Applies the cuts (`use_occlusion` and `config` as trialCuts had them: a cut by the data moves the pixels it
  /// moved there); cut c becomes motion label labelCount()-1+c (before the outlier label). Resets the dual variables.
  virtual void applyCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) = 0;
  /// @brief One pass over the pixels: the cost model of every motion label at `twists`, with the occlusion
  /// mask of the labels' level when `use_occlusion`.
  virtual LabelCostModel costModel(const std::vector<Vector6d>& twists, bool use_occlusion, const Config& config) = 0;
  /// @brief costModel at each set of twists (one set per motion label each), one model per set: the CUDA backend
  /// runs them as one batched pass and waits once; the default calls costModel per set.
  virtual std::vector<LabelCostModel> costModels(const std::vector<std::vector<Vector6d>>& twist_sets,
                                                 bool use_occlusion, const Config& config);
  /// @brief refitUnions (below; its arguments checked there, `batches` = unionBatches(groups)) where the sums are,
  /// when the store can do it without the host: the CUDA backend runs the passes and the steps on the device and waits
  /// once. False (the default): the store cannot, and refitUnions runs its host loop over costModels.
  virtual bool refitUnionsWhereTheSumsAre(const std::vector<Vector6d>& twists,
                                          const std::vector<std::vector<int>>& groups, const std::vector<int>& batches,
                                          const std::vector<Vector6d>& starts, int iterations, bool use_occlusion,
                                          const Config& config, std::vector<UnionFit>& fits) {
    (void)twists, (void)groups, (void)batches, (void)starts, (void)iterations, (void)use_occlusion, (void)config,
        (void)fits;
    return false;
  }
  /// @brief refitPairsFromTheBetterMotion (below; its arguments checked there) where the sums are: the CUDA backend
  /// runs the swapped pass, the choice of each pair's start and the refit's passes and steps on the device and waits
  /// once. False (the default): the store cannot, and the host chooses between the passes.
  virtual bool refitPairsWhereTheSumsAre(const std::vector<Vector6d>& twists,
                                         const std::vector<std::vector<int>>& pairs, const std::vector<int>& batches,
                                         const std::vector<double>& own_cost, int iterations, bool use_occlusion,
                                         const Config& config, std::vector<UnionFit>& fits) {
    (void)twists, (void)pairs, (void)batches, (void)own_cost, (void)iterations, (void)use_occlusion, (void)config,
        (void)fits;
    return false;
  }
};

/// @brief Which pass each group of refitUnions shares: groups are taken in order, each into the first batch none of
/// whose groups holds one of its labels (labels of one batch's groups are disjoint, so one set of twists serves them
/// all). Batch numbers start at 0.
std::vector<int> unionBatches(const std::vector<std::vector<int>>& groups);

/// @brief H with the label-count update's relative ridge (1e-6 of its largest diagonal entry): the 6x6 solves stay
/// defined for planar or textureless segments, whose pixels leave directions unconstrained.
Matrix6d withRidge(const Matrix6d& H);

/// @brief One pass over the level's pixels: the cost model of every motion label of `u` at `twists`.
LabelCostModel labelCostModel(const PyramidLevel& frame1, const PyramidLevel& frame2, const SoftLabels& u,
                              const ImageU8* occluded, const std::vector<Vector6d>& twists, const Config& config,
                              MotionAccumulator& accumulator);

/// @brief The cost model of `motion_labels` labels from the diagonal blocks of one accumulation.
LabelCostModel costModelFromEquations(const MotionNormalEquations& equations, int motion_labels);

/// @brief Predicted data-cost increase when labels a and b share one motion (the best one for both):
/// (xi_a - xi_b)^T H_a (H_a + H_b)^-1 H_b (xi_a - xi_b). It measures how differently the two motions move
/// the segments' own pixels, weighted by how well those pixels constrain each direction.
double mergeCostIncrease(const Matrix6d& H_a, const Matrix6d& H_b, const Vector6d& xi_a, const Vector6d& xi_b);

/// @brief The label cost [normalised Cauchy cost]: label_cost per valid pixel at the label level.
double labelCost(const Config& config, int valid_pixels);

/// @brief Merges, cheapest first, every pair whose predicted increase is below the label cost; the merged
/// label takes the union's best motion (H_a + H_b)^-1 (H_a xi_a + H_b xi_b) and model H_a + H_b, so the
/// n x n table is updated, not recomputed. Then, when `remove_small`, labels with support below
/// min_support_fraction * valid_pixels go to the outlier label. The labels change once, by one remap.
/// Keeps the labels, twists and model consistent.
///
/// `lineage` (stream mode; null: a pair on its own): per motion label, its LabelLineage. Merging two carried labels
/// also pays warm_switch_cost per unit of the smaller label's support (the pixels whose segment would change); the
/// merged label takes mergedLineage. Kept in step with the labels.
AdaptationStats adaptLabelCount(LabelStore& labels, std::vector<Vector6d>& twists, LabelCostModel& model,
                                int valid_pixels, const Config& config, bool remove_small = true,
                                std::vector<LabelLineage>* lineage = nullptr);

/// @brief Proposes to split each large label in two, across its principal 3D axis and by the data (its pixels that pay
/// more than kSplitCostFactor times its cost per pixel: LabelCut::cost_above), predicts the data-cost decrease of
/// giving each half its own Gauss-Newton motion (one pass over the pixels per family of cuts), and splits, with the
/// better-paying cut of each label, those whose decrease exceeds the label cost (largest first, at most
/// max_splits_per_iteration). The halves start from their Gauss-Newton motions; the next motion step refines them.
AdaptationStats proposeSplits(LabelStore& labels, std::vector<Vector6d>& twists, bool use_occlusion, int valid_pixels,
                              const Config& config);

/// @brief Config::merge_occlusion_absorbers (needs detect_occlusions): each motion label's data cost under its own
/// motion, with the occlusion mask of the current motions, against its cost when it and every other label take the
/// motion of the label with the largest support, with the occlusion mask of that trial (pixels a motion sends out of
/// view or behind frame 2 pay nothing in either, as in the energy). A label whose increase plus the switching cost of
/// two carried labels is below the price (priceFor of the two labels' costs under their own motions) merges into the
/// largest label, which keeps its motion. Two accumulator passes and two occlusion updates (a third after a merge); it
/// leaves the backend with the occlusion mask of the labels and twists it returns, so the caller needs no update of its
/// own (the solver runs it in place of the one before the label steps of the second and later outer iterations).
/// Throws InputError on mismatched sizes.
AdaptationStats mergeOcclusionAbsorbers(SolveBackend& backend, std::vector<Vector6d>& twists, int valid_pixels,
                                        const Config& config, std::vector<LabelLineage>* lineage = nullptr);

/// @brief For each group of motion labels (lists of label indices; a label may be in several groups), one rigid motion
/// for the union of their pixels: Gauss-Newton with per-group Levenberg-Marquardt backtracking from `starts` (one per
/// group), the other labels keeping `twists`. Groups with disjoint labels share a pass (unionBatches: a batch of them
/// is one set of twists, as labels that share a twist form one label of the interpolation model); each iteration is one
/// batched pass (LabelStore::costModels) for all, plus one at the starts. A group's fit depends only on its own batch.
/// Steps are capped at 0.1 m / 0.1 rad. Throws InputError on mismatched sizes, an empty group, a label outside [0, n)
/// or twice in one group.
std::vector<UnionFit> refitUnions(LabelStore& labels, const std::vector<Vector6d>& twists,
                                  const std::vector<std::vector<int>>& groups, const std::vector<Vector6d>& starts,
                                  int iterations, bool use_occlusion, const Config& config);

/// @brief For each pair {a, b} of motion labels, one motion refitted on the union of their pixels (refitUnions,
/// `iterations` steps) from the better of the two motions: a's where own_cost[a] plus what b's pixels pay under a's
/// motion is at most what a's pixels pay under b's motion plus own_cost[b], else b's (each side under the other's
/// motion: one pass per batch, the batch's pairs swapped). `batches` = unionBatches(pairs) (the pairs of a batch are
/// disjoint); `own_cost` holds each motion label's cost under its own twist. Throws InputError on mismatched sizes or a
/// pair that is not two distinct labels.
std::vector<UnionFit> refitPairsFromTheBetterMotion(LabelStore& labels, const std::vector<Vector6d>& twists,
                                                    const std::vector<std::vector<int>>& pairs,
                                                    const std::vector<int>& batches,
                                                    const std::vector<double>& own_cost, int iterations,
                                                    bool use_occlusion, const Config& config);

/// @brief mergeWhereOneMotionExplains refits a pair (and estimateStaticWorld tests a segment under the world's motion)
/// only where the quadratic model predicts an increase below this many times what may be paid: the model is exact near
/// the optima and errs by a small factor away from them (measured on the TUM excerpt: docs/ALGORITHM.md), while
/// distinct motions are priced hundreds of times above.
inline constexpr double kRefitCandidateRatio = 20.0;

/// @brief What the merge test of two labels a and b measured: each one's data cost under its own motion (own_*), how
/// much more its pixels pay under the motion refitted on the union (increase_*), its weighted pixels, and the data
/// term's noise level (the cost per pixel of the widest label under its own motion).
struct MergeEvidence {
  double own_a = 0, own_b = 0, increase_a = 0, increase_b = 0, pixels_a = 0, pixels_b = 0, noise_per_pixel = 0;
};

/// @brief Whether one rigid motion explains two labels: each side's increase is at most own_tolerance times what it
/// pays under its own motion AND at most noise_tolerance times the noise level per pixel of its own. Each side is
/// judged by its own pixels (a small part whose pixels one motion explains badly is not hidden by a large background);
/// the first bound scales with the side's own fit, the second with the scene's (neither alone separated the moving
/// parts of the synthetic scenes from the pieces of a real static office: docs/decisions). A tolerance <= 0: never.
/// The absolute label price plays no part here: it is adaptLabelCount's, where a stream's switching cost applies too.
bool oneMotionExplains(const MergeEvidence& evidence, double own_tolerance, double noise_tolerance);

/// @brief Config::merge_refit_tolerance, merge_refit_tolerance_parts and merge_refit_noise_tolerance: pairs of motion
/// labels, most alike first (by the quadratic model), tested by
/// refitting one motion on each pair's union (refitUnions from the better of the two motions, merge_refit_iterations
/// steps) and merged when oneMotionExplains, most alike first and each label in at most one merge per round. A round
/// tests the pairs of the first few unionBatches of the candidates (as many batches as make about 4 x 160 x 120 pixel
/// evaluations over `valid_pixels`, the label level's: at full depth coverage 4 at 160x120, 1 from 320x240 on; on the
/// GPU a round's batches share their launches); pairs refused since the labels last changed are not tested again;
/// repeated until no candidate is left. No switching cost: a stream's carried segments that one motion explains merge
/// like any others, with two differences that keep a stream's parts through a brief rest: two carried labels are judged
/// with merge_refit_tolerance_parts (the stream kept them apart a pair ago), and two that movedApartBefore by
/// merge_memory_displacement are not tested in this pair (a part merges after a pair at rest, not at the turn of its
/// motion). The merged label takes the refitted motion and mergedLineage. Costs one accumulator pass for the labels'
/// own costs (none when `own_model`, the labels' LabelStore::costModel under `twists`, is given) and 2 +
/// merge_refit_iterations (batched) passes per round. Throws InputError on mismatched sizes.
AdaptationStats mergeWhereOneMotionExplains(LabelStore& labels, std::vector<Vector6d>& twists, int valid_pixels,
                                            bool use_occlusion, const Config& config,
                                            std::vector<LabelLineage>* lineage = nullptr,
                                            const LabelCostModel* own_model = nullptr);

/// @brief A LabelStore over host soft labels at one pyramid level (the CPU backend's, and the tests').
class HostLabelStore final : public LabelStore {
 public:
  /// `occluded` may be null; `accumulator` null = a CPU one. All must outlive the store.
  HostLabelStore(SoftLabels& u, const PyramidLevel& frame1, const PyramidLevel& frame2, const ImageU8* occluded,
                 MotionAccumulator* accumulator = nullptr);
  int labelCount() const override { return u_.count; }
  std::vector<double> supports() override;
  void remap(const std::vector<int>& target, int new_count) override;
  std::vector<LabelMoments> ownedMoments() override;
  CutTrial trialCuts(const std::vector<LabelCut>& cuts, const std::vector<Vector6d>& twists, bool use_occlusion,
                     const Config& config) override;
  void applyCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) override;
  LabelCostModel costModel(const std::vector<Vector6d>& twists, bool use_occlusion, const Config& config) override;

 private:
  SoftLabels& u_;
  const PyramidLevel& frame1_;
  const PyramidLevel& frame2_;
  const ImageU8* occluded_;
  /// The labels with `cuts` applied (count + cuts planes) and the pixels each moved.
  SoftLabels withCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config,
                      std::vector<double>& moved) const;
  std::unique_ptr<MotionAccumulator> own_accumulator_;
  MotionAccumulator* accumulator_;
};

/// @brief Checks a remap target (sizes, ranges, the outlier staying last); throws InputError naming the value.
void validateRemap(const std::vector<int>& target, int old_count, int new_count);

/// @brief Support-weighted centroid of each motion label's points (points: 3 channel, NaN invalid).
std::vector<Eigen::Vector3d> labelCentroids(const SoftLabels& u, const ImageF& points);

}  // namespace mc_flow
