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
AdaptationStats adaptLabelCount(SoftLabels& u, std::vector<Vector6d>& twists, const ImageF& points, int valid_pixels,
                                const Config& config);

}  // namespace mc_flow
