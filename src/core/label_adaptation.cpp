// Label count adaptation (section 5): similar motions are merged, tiny labels handed to the outlier label
// (the next label step redistributes those pixels to whichever motion explains them).
#include "mc_flow/core/label_adaptation.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace mc_flow {

std::vector<Eigen::Vector3d> labelCentroids(const SoftLabels& u, const ImageF& points) {
  const int motion_labels = u.count - 1;
  std::vector<Eigen::Vector3d> sums(std::size_t(motion_labels), Eigen::Vector3d::Zero());
  std::vector<double> weights(std::size_t(motion_labels), 0.0);
  const std::size_t plane = u.planeSize();
  for (std::size_t idx = 0; idx < plane; ++idx) {
    const float z = points.data[idx * 3 + 2];
    if (!std::isfinite(z)) continue;
    const Eigen::Vector3d P(points.data[idx * 3], points.data[idx * 3 + 1], z);
    for (int i = 0; i < motion_labels; ++i) {
      const double w = u.data[std::size_t(i) * plane + idx];
      if (w <= 0) continue;
      sums[std::size_t(i)] += w * P;
      weights[std::size_t(i)] += w;
    }
  }
  for (int i = 0; i < motion_labels; ++i)
    if (weights[std::size_t(i)] > 0) sums[std::size_t(i)] /= weights[std::size_t(i)];
  return sums;
}

namespace {

// How differently two motions move a point, and the angle between their rotations.
void motionDifference(const Vector6d& a, const Vector6d& b, const Eigen::Vector3d& ca, const Eigen::Vector3d& cb,
                      double& displacement, double& angle) {
  const Eigen::Matrix4d Ta = se3Exp(a), Tb = se3Exp(b);
  const Eigen::Vector3d da = (Ta - Tb).topLeftCorner<3, 3>() * ca + (Ta - Tb).topRightCorner<3, 1>();
  const Eigen::Vector3d db = (Ta - Tb).topLeftCorner<3, 3>() * cb + (Ta - Tb).topRightCorner<3, 1>();
  displacement = std::max(da.norm(), db.norm());
  const Eigen::Matrix3d R = Ta.topLeftCorner<3, 3>().transpose() * Tb.topLeftCorner<3, 3>();
  angle = Eigen::AngleAxisd(R).angle();
}

}  // namespace

bool motionsSimilar(const Vector6d& a, const Vector6d& b, const Eigen::Vector3d& centroid_a,
                    const Eigen::Vector3d& centroid_b, const Config& config) {
  double displacement, angle;
  motionDifference(a, b, centroid_a, centroid_b, displacement, angle);
  return displacement < config.merge_translation && angle < config.merge_rotation;
}

double extraDataCost(const SoftLabels& u, const std::vector<const float*>& planes, int i, int j) {
  const std::size_t n = u.planeSize();
  const float* uj = u.plane(j);
  const float* Di = planes[std::size_t(i)];
  const float* Dj = planes[std::size_t(j)];
  double sum = 0, weight = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (uj[k] < 0.5f) continue;  // the label's own pixels, not the fringes it shares
    sum += double(uj[k]) * (Di[k] - Dj[k]);
    weight += uj[k];
  }
  return weight > 0 ? sum / weight : 0.0;
}

AdaptationStats adaptLabelCount(SoftLabels& u, std::vector<Vector6d>& twists, const ImageF& points, int valid_pixels,
                                const Config& config, const std::vector<float>* data_cost) {
  AdaptationStats stats;
  // Data-cost planes follow the labels through merges (the kept label keeps its plane: its twist moves by
  // less than the merge thresholds, so its costs barely change).
  std::vector<const float*> planes;
  if (data_cost && data_cost->size() == u.data.size())
    for (int i = 0; i < u.count; ++i) planes.push_back(data_cost->data() + std::size_t(i) * u.planeSize());
  // Merge the most similar pair first, then re-evaluate: merging changes centroids and twists.
  for (;;) {
    const int motion_labels = u.count - 1;
    if (motion_labels < 2) break;
    const std::vector<Eigen::Vector3d> centroids = labelCentroids(u, points);
    double best = std::numeric_limits<double>::infinity();
    int best_a = -1, best_b = -1;
    for (int a = 0; a < motion_labels; ++a)
      for (int b = a + 1; b < motion_labels; ++b) {
        double displacement, angle;
        motionDifference(twists[std::size_t(a)], twists[std::size_t(b)], centroids[std::size_t(a)],
                         centroids[std::size_t(b)], displacement, angle);
        // Rank candidates on one scale: the twist test by displacement relative to its threshold, the
        // data test by extra cost relative to its threshold.
        double score = std::numeric_limits<double>::infinity();
        if (displacement < config.merge_translation && angle < config.merge_rotation)
          score = displacement / config.merge_translation;
        if (!planes.empty() && config.merge_data_cost > 0) {
          const double extra = std::max(extraDataCost(u, planes, a, b), extraDataCost(u, planes, b, a));
          if (extra < config.merge_data_cost) score = std::min(score, std::max(0.0, extra) / config.merge_data_cost);
        }
        if (score < best) {
          best = score;
          best_a = a;
          best_b = b;
        }
      }
    if (best_a < 0) break;
    const double sa = u.support(best_a), sb = u.support(best_b);
    const int keep = sa >= sb ? best_a : best_b, drop = sa >= sb ? best_b : best_a;
    if (sa + sb > 0) twists[std::size_t(keep)] = (sa * twists[std::size_t(best_a)] + sb * twists[std::size_t(best_b)]) / (sa + sb);
    u.mergeInto(drop, keep);
    twists.erase(twists.begin() + drop);
    if (!planes.empty()) planes.erase(planes.begin() + drop);
    ++stats.merged;
  }
  // Remove labels with too little support (always keep at least one motion label).
  const double min_support = config.min_support_fraction * double(valid_pixels);
  for (int i = u.count - 2; i >= 0; --i) {
    if (u.count - 1 <= 1) break;
    if (u.support(i) < min_support) {
      u.mergeInto(i, u.outlier());
      twists.erase(twists.begin() + i);
      ++stats.removed;
    }
  }
  return stats;
}

}  // namespace mc_flow
