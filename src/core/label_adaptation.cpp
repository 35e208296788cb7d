// Label count (section 5) decided on the energy: merge when one motion explains two labels almost as well
// as two motions, split when two explain one much better, each against the label cost. See
// docs/ALGORITHM.md, "Label count".
#include "mc_flow/core/label_adaptation.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "mc_flow/core/error.h"

namespace mc_flow {

namespace {

// Relative ridge on the 6x6 solves: a planar or textureless segment leaves directions unconstrained.
constexpr double kRidge = 1e-6;

Matrix6d regularised(const Matrix6d& H) {
  const double scale = std::max(H.diagonal().maxCoeff(), 1e-12);
  return H + kRidge * scale * Matrix6d::Identity();
}

// Newton decrement g^T H^-1 g: how much the cost falls when the label takes its Gauss-Newton step.
double newtonDecrement(const Matrix6d& H, const Vector6d& g) {
  return g.dot(regularised(H).ldlt().solve(g));
}

Vector6d gaussNewtonStep(const Matrix6d& H, const Vector6d& g) {
  // The motion step's step limits: 5 cm and 0.1 rad per update, so one bad linearisation cannot fling
  // a new label far away.
  Vector6d d = -regularised(H).ldlt().solve(g);
  const double scale = std::max({1.0, d.head<3>().norm() / 0.05, d.tail<3>().norm() / 0.1});
  return d / scale;
}

}  // namespace

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

LabelCostModel labelCostModel(const PyramidLevel& frame1, const PyramidLevel& frame2, const SoftLabels& u,
                              const ImageU8* occluded, const std::vector<Vector6d>& twists, const Config& config,
                              MotionAccumulator& accumulator) {
  const int n = u.count - 1;
  if (int(twists.size()) != n)
    throw InputError("labelCostModel: " + std::to_string(twists.size()) + " twists for " + std::to_string(n) +
                     " motion labels");
  accumulator.setLevel(frame1, frame2, u, occluded, config);
  MotionNormalEquations equations;
  accumulator.accumulate(twists, equations);
  LabelCostModel model;
  model.curvature.resize(std::size_t(n));
  model.gradient.resize(std::size_t(n));
  for (int i = 0; i < n; ++i) {
    model.curvature[std::size_t(i)] = equations.H.block<6, 6>(6 * i, 6 * i);
    model.gradient[std::size_t(i)] = equations.g.segment<6>(6 * i);
  }
  return model;
}

double mergeCostIncrease(const Matrix6d& H_a, const Matrix6d& H_b, const Vector6d& xi_a, const Vector6d& xi_b) {
  const Vector6d d = xi_a - xi_b;
  // H_a (H_a + H_b)^-1 H_b is the "parallel sum" of the two curvatures: symmetric, positive semidefinite.
  const Vector6d Hb_d = H_b * d;
  return std::max(0.0, (H_a * d).dot(regularised(H_a + H_b).ldlt().solve(Hb_d)));
}

double labelCost(const Config& config, int valid_pixels) { return config.label_cost * double(valid_pixels); }

AdaptationStats adaptLabelCount(SoftLabels& u, std::vector<Vector6d>& twists, LabelCostModel& model, int valid_pixels,
                                const Config& config, bool remove_small) {
  AdaptationStats stats;
  stats.smallest_refused_merge = std::numeric_limits<double>::infinity();
  const int n0 = u.count - 1;
  if (int(twists.size()) != n0 || int(model.curvature.size()) != n0)
    throw InputError("adaptLabelCount: " + std::to_string(twists.size()) + " twists and " +
                     std::to_string(model.curvature.size()) + " cost models for " + std::to_string(n0) +
                     " motion labels");
  const double price = labelCost(config, valid_pixels);
  // n x n table of predicted increases; after a merge only the merged label's row and column change.
  std::vector<std::vector<double>> increase(std::size_t(n0), std::vector<double>(std::size_t(n0), 0.0));
  auto fill = [&](int a, int b) {
    const double v = mergeCostIncrease(model.curvature[std::size_t(a)], model.curvature[std::size_t(b)],
                                       twists[std::size_t(a)], twists[std::size_t(b)]);
    increase[std::size_t(a)][std::size_t(b)] = increase[std::size_t(b)][std::size_t(a)] = v;
  };
  for (int a = 0; a < n0; ++a)
    for (int b = a + 1; b < n0; ++b) fill(a, b);
  for (;;) {
    const int n = u.count - 1;
    double best = std::numeric_limits<double>::infinity();
    int best_a = -1, best_b = -1;
    for (int a = 0; a < n; ++a)
      for (int b = a + 1; b < n; ++b)
        if (increase[std::size_t(a)][std::size_t(b)] < best) {
          best = increase[std::size_t(a)][std::size_t(b)];
          best_a = a;
          best_b = b;
        }
    if (best_a < 0 || !(best < price)) {
      stats.smallest_refused_merge = best;
      break;
    }
    const int keep = u.support(best_a) >= u.support(best_b) ? best_a : best_b;
    const int drop = keep == best_a ? best_b : best_a;
    const Matrix6d H = model.curvature[std::size_t(keep)] + model.curvature[std::size_t(drop)];
    twists[std::size_t(keep)] = regularised(H).ldlt().solve(model.curvature[std::size_t(keep)] * twists[std::size_t(keep)] +
                                                            model.curvature[std::size_t(drop)] * twists[std::size_t(drop)]);
    model.curvature[std::size_t(keep)] = H;
    model.gradient[std::size_t(keep)] += model.gradient[std::size_t(drop)];
    u.mergeInto(drop, keep);
    twists.erase(twists.begin() + drop);
    model.curvature.erase(model.curvature.begin() + drop);
    model.gradient.erase(model.gradient.begin() + drop);
    increase.erase(increase.begin() + drop);
    for (auto& row : increase) row.erase(row.begin() + drop);
    const int kept = keep > drop ? keep - 1 : keep;
    for (int c = 0; c < u.count - 1; ++c)
      if (c != kept) fill(kept, c);
    ++stats.merged;
  }
  if (!remove_small) return stats;
  // Remove labels with too little support (always keep at least one motion label).
  const double min_support = config.min_support_fraction * double(valid_pixels);
  for (int i = u.count - 2; i >= 0; --i) {
    if (u.count - 1 <= 1) break;
    if (u.support(i) < min_support) {
      u.mergeInto(i, u.outlier());
      twists.erase(twists.begin() + i);
      model.curvature.erase(model.curvature.begin() + i);
      model.gradient.erase(model.gradient.begin() + i);
      ++stats.removed;
    }
  }
  return stats;
}

AdaptationStats proposeSplits(SoftLabels& u, std::vector<Vector6d>& twists, const PyramidLevel& frame1,
                              const PyramidLevel& frame2, const ImageU8* occluded, int valid_pixels,
                              const Config& config, MotionAccumulator& accumulator) {
  AdaptationStats stats;
  const int n = u.count - 1;
  const int room = config.max_labels - n;
  if (room <= 0 || config.max_splits_per_iteration <= 0) return stats;
  const std::size_t plane = u.planeSize();
  const ImageF& points = frame1.points;
  const double min_half = std::max(2.0 * config.min_support_fraction * double(valid_pixels), 32.0);

  // Each candidate's own pixels (u >= 0.5) split at its centroid across its principal axis: the two
  // halves of a segment that holds two parts are, for compact parts, its two ends.
  std::vector<int> candidate_of_label(std::size_t(n), -1), parent;
  std::vector<std::vector<std::size_t>> second_half;
  for (int i = 0; i < n; ++i) {
    const float* ui = u.plane(i);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    double count = 0;
    for (std::size_t k = 0; k < plane; ++k) {
      if (ui[k] < 0.5f || !std::isfinite(points.data[k * 3 + 2])) continue;
      const Eigen::Vector3d P(points.data[k * 3], points.data[k * 3 + 1], points.data[k * 3 + 2]);
      mean += P;
      scatter += P * P.transpose();
      ++count;
    }
    if (count < 2 * min_half) continue;
    mean /= count;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter / count - mean * mean.transpose());
    const Eigen::Vector3d axis = eigen.eigenvectors().col(2);
    std::vector<std::size_t> half;
    for (std::size_t k = 0; k < plane; ++k) {
      if (ui[k] < 0.5f || !std::isfinite(points.data[k * 3 + 2])) continue;
      const Eigen::Vector3d P(points.data[k * 3], points.data[k * 3 + 1], points.data[k * 3 + 2]);
      if ((P - mean).dot(axis) > 0) half.push_back(k);
    }
    if (double(half.size()) < min_half || count - double(half.size()) < min_half) continue;
    candidate_of_label[std::size_t(i)] = int(parent.size());
    parent.push_back(i);
    second_half.push_back(std::move(half));
  }
  if (parent.empty()) return stats;

  // All candidates at once: the second halves become extra labels (hard labels barely interact), and
  // one pass gives every half's cost model at the parent's twist.
  const int m = int(parent.size());
  SoftLabels trial(u.width, u.height, n + m + 1, 0.f);
  for (int i = 0; i < n; ++i) std::copy_n(u.plane(i), plane, trial.plane(i));
  std::copy_n(u.plane(u.outlier()), plane, trial.plane(trial.outlier()));
  std::vector<Vector6d> trial_twists = twists;
  for (int c = 0; c < m; ++c) {
    const int p = parent[std::size_t(c)];
    for (std::size_t k : second_half[std::size_t(c)]) {
      trial.plane(n + c)[k] = trial.plane(p)[k];
      trial.plane(p)[k] = 0.f;
    }
    trial_twists.push_back(twists[std::size_t(p)]);
  }
  const LabelCostModel model = labelCostModel(frame1, frame2, trial, occluded, trial_twists, config, accumulator);

  const double price = labelCost(config, valid_pixels);
  std::vector<std::pair<double, int>> gains;
  for (int c = 0; c < m; ++c) {
    const int p = parent[std::size_t(c)];
    const Matrix6d& H1 = model.curvature[std::size_t(p)];
    const Matrix6d& H2 = model.curvature[std::size_t(n + c)];
    const Vector6d& g1 = model.gradient[std::size_t(p)];
    const Vector6d& g2 = model.gradient[std::size_t(n + c)];
    // What two motions gain over the one best motion for the whole label.
    const double gain = newtonDecrement(H1, g1) + newtonDecrement(H2, g2) - newtonDecrement(H1 + H2, g1 + g2);
    if (gain > price) gains.emplace_back(gain, c);
  }
  std::sort(gains.begin(), gains.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  const int take = std::min({int(gains.size()), room, config.max_splits_per_iteration});
  if (take == 0) return stats;
  // The taken second halves become labels n .. n+take-1, before the outlier label: one new labelling.
  SoftLabels grown(u.width, u.height, u.count + take, 0.f);
  for (int i = 0; i < n; ++i) std::copy_n(u.plane(i), plane, grown.plane(i));
  std::copy_n(u.plane(u.outlier()), plane, grown.plane(grown.outlier()));
  for (int t = 0; t < take; ++t) {
    const int c = gains[std::size_t(t)].second;
    const int p = parent[std::size_t(c)];
    const Vector6d base = twists[std::size_t(p)];
    twists[std::size_t(p)] = base + gaussNewtonStep(model.curvature[std::size_t(p)], model.gradient[std::size_t(p)]);
    twists.push_back(base + gaussNewtonStep(model.curvature[std::size_t(n + c)], model.gradient[std::size_t(n + c)]));
    float* from = grown.plane(p);
    float* to = grown.plane(n + t);
    for (std::size_t k : second_half[std::size_t(c)]) {
      to[k] = from[k];
      from[k] = 0.f;
    }
    ++stats.split;
  }
  u = std::move(grown);
  return stats;
}

}  // namespace mc_flow
