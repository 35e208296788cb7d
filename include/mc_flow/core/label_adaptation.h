/**
 * @file label_adaptation.h
 * @brief Label count (section 5): merge labels with similar motions, move tiny labels to the outlier label.
 */
#pragma once

#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

struct AdaptationStats {
  int merged = 0;
  int removed = 0;
};

/// @brief Support-weighted centroid of each motion label's points (points: 3 channel, NaN invalid).
std::vector<Eigen::Vector3d> labelCentroids(const SoftLabels& u, const ImageF& points);

/// @brief True when the two motions move both centroids differently by less than merge_translation
/// and their rotation angles differ by less than merge_rotation.
bool motionsSimilar(const Vector6d& a, const Vector6d& b, const Eigen::Vector3d& centroid_a,
                    const Eigen::Vector3d& centroid_b, const Config& config);

/// @brief Merges similar labels (support-weighted twist average), then moves labels whose support is
/// below min_support_fraction * valid_pixels into the outlier label. Keeps u and twists consistent.
/// With `data_cost` (the label step's D_i planes for the current twists, same label order as u), two labels
/// also merge when each one's motion explains the other's pixels almost as well as their own: the mean
/// extra data cost is below merge_data_cost both ways. This catches equal motions whose twists differ in
/// directions the data does not constrain (a flat patch sliding along itself), which the twist test misses.
AdaptationStats adaptLabelCount(SoftLabels& u, std::vector<Vector6d>& twists, const ImageF& points, int valid_pixels,
                                const Config& config, const std::vector<float>* data_cost = nullptr);

/// @brief Mean extra data cost per pixel when the pixels of label j (weighted by u_j) take label i's motion:
/// sum_x u_j (D_i - D_j) / sum_x u_j. Planes as in LabelProblem::data_cost.
double extraDataCost(const SoftLabels& u, const std::vector<const float*>& planes, int i, int j);

}  // namespace mc_flow
