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

#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

struct AdaptationStats {
  int merged = 0;
  int removed = 0;
  int split = 0;
  /// Smallest predicted data-cost increase of a merge that was refused (infinity when none was left)
  /// [normalised Cauchy cost, summed over the label level's pixels].
  double smallest_refused_merge = 0;
};

/// @brief Each motion label's data cost near its twist xi_i: E_i(xi_i + d) ~ E_i + 2 g_i^T d + d^T H_i d
/// (Gauss-Newton on the normalised Cauchy cost, the motion step's diagonal blocks).
struct LabelCostModel {
  std::vector<Matrix6d> curvature;  ///< H_i
  std::vector<Vector6d> gradient;   ///< g_i
};

/// @brief One pass over the level's pixels: the cost model of every motion label of `u` at `twists`.
LabelCostModel labelCostModel(const PyramidLevel& frame1, const PyramidLevel& frame2, const SoftLabels& u,
                              const ImageU8* occluded, const std::vector<Vector6d>& twists, const Config& config,
                              MotionAccumulator& accumulator);

/// @brief Predicted data-cost increase when labels a and b share one motion (the best one for both):
/// (xi_a - xi_b)^T H_a (H_a + H_b)^-1 H_b (xi_a - xi_b). It measures how differently the two motions move
/// the segments' own pixels, weighted by how well those pixels constrain each direction.
double mergeCostIncrease(const Matrix6d& H_a, const Matrix6d& H_b, const Vector6d& xi_a, const Vector6d& xi_b);

/// @brief The label cost [normalised Cauchy cost]: label_cost per valid pixel at the label level.
double labelCost(const Config& config, int valid_pixels);

/// @brief Merges, cheapest first, every pair whose predicted increase is below the label cost; the merged
/// label takes the union's best motion (H_a + H_b)^-1 (H_a xi_a + H_b xi_b) and model H_a + H_b, so the
/// n x n table is updated, not recomputed. Then, when `remove_small`, labels with support below
/// min_support_fraction * valid_pixels go to the outlier label. Keeps u, twists and model consistent.
AdaptationStats adaptLabelCount(SoftLabels& u, std::vector<Vector6d>& twists, LabelCostModel& model, int valid_pixels,
                                const Config& config, bool remove_small = true);

/// @brief Proposes to split each large label in two along its principal 3D axis, predicts the data-cost
/// decrease of giving each half its own Gauss-Newton motion (one pass over the pixels for all
/// candidates), and splits those whose decrease exceeds the label cost (largest first, at most
/// max_splits_per_iteration). The halves start from their Gauss-Newton motions; the next motion step
/// refines them.
AdaptationStats proposeSplits(SoftLabels& u, std::vector<Vector6d>& twists, const PyramidLevel& frame1,
                              const PyramidLevel& frame2, const ImageU8* occluded, int valid_pixels,
                              const Config& config, MotionAccumulator& accumulator);

/// @brief Support-weighted centroid of each motion label's points (points: 3 channel, NaN invalid).
std::vector<Eigen::Vector3d> labelCentroids(const SoftLabels& u, const ImageF& points);

}  // namespace mc_flow
