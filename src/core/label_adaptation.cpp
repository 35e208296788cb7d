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
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/union_refit_step.h"

namespace mc_flow {

namespace {

using union_refit::kRidge;

// mergeWhereOneMotionExplains: a round tests as many batches of disjoint pairs as make about this many pixel
// evaluations over the label level's valid pixels (at full depth coverage 4 batches at 160x120, 1 from 320x240 on;
// there a pass fills the GPU by itself).
constexpr int kMergeRoundPixels = 4 * 160 * 120;

// Newton decrement g^T H^-1 g: how much the cost falls when the label takes its Gauss-Newton step.
double newtonDecrement(const Matrix6d& H, const Vector6d& g) { return g.dot(withRidge(H).ldlt().solve(g)); }

Vector6d gaussNewtonStep(const Matrix6d& H, const Vector6d& g) {
  // The motion step's step limits: 5 cm and 0.1 rad per update, so one bad linearisation cannot fling
  // a new label far away.
  Vector6d d = -withRidge(H).ldlt().solve(g);
  const double scale = std::max({1.0, d.head<3>().norm() / 0.05, d.tail<3>().norm() / 0.1});
  return d / scale;
}

}  // namespace

Matrix6d withRidge(const Matrix6d& H) {
  const double scale = std::max(H.diagonal().maxCoeff(), 1e-12);
  return H + kRidge * scale * Matrix6d::Identity();
}

Eigen::Vector3d LabelMoments::principalAxis() const {
  const Eigen::Vector3d centre = mean();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(outer / count - centre * centre.transpose());
  return eigen.eigenvectors().col(2);
}

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
  accumulator.accumulateLabelBlocks(twists, equations);
  return costModelFromEquations(equations, n);
}

LabelCostModel costModelFromEquations(const MotionNormalEquations& equations, int motion_labels) {
  if (equations.g.size() != 6 * motion_labels)
    throw InputError("costModelFromEquations: normal equations of " + std::to_string(equations.g.size() / 6) +
                     " labels, expected " + std::to_string(motion_labels));
  LabelCostModel model;
  model.curvature.resize(std::size_t(motion_labels));
  model.gradient.resize(std::size_t(motion_labels));
  model.cost.resize(std::size_t(motion_labels));
  model.pixels.resize(std::size_t(motion_labels));
  for (int i = 0; i < motion_labels; ++i) {
    model.curvature[std::size_t(i)] = equations.H.block<6, 6>(6 * i, 6 * i);
    model.gradient[std::size_t(i)] = equations.g.segment<6>(6 * i);
    model.cost[std::size_t(i)] = equations.label_cost(i);
    model.pixels[std::size_t(i)] = equations.label_pixels.size() > i ? equations.label_pixels(i) : 0.0;
  }
  return model;
}

double mergeCostIncrease(const Matrix6d& H_a, const Matrix6d& H_b, const Vector6d& xi_a, const Vector6d& xi_b) {
  const Vector6d d = xi_a - xi_b;
  // H_a (H_a + H_b)^-1 H_b is the "parallel sum" of the two curvatures: symmetric, positive semidefinite.
  const Vector6d Hb_d = H_b * d;
  return std::max(0.0, (H_a * d).dot(withRidge(H_a + H_b).ldlt().solve(Hb_d)));
}

double labelCost(const Config& config, int valid_pixels) { return config.label_cost * double(valid_pixels); }

// The price of keeping two motions apart where the two labels pay cost_a and cost_b now: the absolute price, or the
// relative one where that is larger, a fraction of cost_a + cost_b, capped at a share of the smaller label's cost (a
// small part is judged by what it pays, not by the background it would join). The same rule decides merges and
// splits, so a split is not merged back.
double priceFor(double absolute_price, double cost_a, double cost_b, const Config& config) {
  const double a = std::max(0.0, cost_a), b = std::max(0.0, cost_b);
  const double relative =
      std::min(config.label_cost_relative * (a + b), config.label_cost_relative_cap * std::min(a, b));
  return std::max(absolute_price, relative);
}

// Stream mode: merging two labels that both descend from the previous pair's segments changes the smaller one's pixels'
// segment (and id): warm_switch_cost per unit of its support. Nothing outside a stream (no flags) or for a new label.
double mergeSwitchingCost(const std::vector<LabelLineage>* lineage, const std::vector<double>& support, int a, int b,
                          const Config& config) {
  if (!lineage || !(*lineage)[std::size_t(a)].carried || !(*lineage)[std::size_t(b)].carried) return 0.0;
  return config.warm_switch_cost * std::min(support[std::size_t(a)], support[std::size_t(b)]);
}

void validateRemap(const std::vector<int>& target, int old_count, int new_count) {
  if (int(target.size()) != old_count || new_count < 1 || new_count > old_count)
    throw InputError("label remap: " + std::to_string(target.size()) + " targets for " + std::to_string(old_count) +
                     " planes, new count " + std::to_string(new_count));
  for (int i = 0; i < old_count; ++i)
    if (target[std::size_t(i)] < 0 || target[std::size_t(i)] >= new_count)
      throw InputError("label remap: plane " + std::to_string(i) + " maps to " +
                       std::to_string(target[std::size_t(i)]) + ", outside [0, " + std::to_string(new_count) + ")");
  if (target.back() != new_count - 1)
    throw InputError("label remap: the outlier plane must stay last, it maps to " + std::to_string(target.back()));
}

AdaptationStats adaptLabelCount(LabelStore& labels, std::vector<Vector6d>& twists, LabelCostModel& model,
                                int valid_pixels, const Config& config, bool remove_small,
                                std::vector<LabelLineage>* lineage) {
  AdaptationStats stats;
  stats.smallest_refused_merge = std::numeric_limits<double>::infinity();
  const int n0 = labels.labelCount() - 1;
  model.pixels.resize(std::size_t(n0), 0.0);  // a model built by hand may leave the pixel counts out
  if (int(twists.size()) != n0 || int(model.curvature.size()) != n0 || int(model.gradient.size()) != n0 ||
      int(model.cost.size()) != n0)
    throw InputError("adaptLabelCount: " + std::to_string(twists.size()) + " twists and cost models of " +
                     std::to_string(model.curvature.size()) + " curvatures, " + std::to_string(model.gradient.size()) +
                     " gradients and " + std::to_string(model.cost.size()) + " costs for " + std::to_string(n0) +
                     " motion labels");
  if (lineage && int(lineage->size()) != n0)
    throw InputError("adaptLabelCount: " + std::to_string(lineage->size()) + " lineages for " + std::to_string(n0) +
                     " motion labels");
  const double price = labelCost(config, valid_pixels);
  std::vector<double> support = labels.supports();
  auto switchingCost = [&](int a, int b) { return mergeSwitchingCost(lineage, support, a, b, config); };
  // group[i]: the current label of original label i (-1: removed to the outlier label). The labels
  // themselves change once, at the end, by one remap.
  std::vector<int> group(static_cast<std::size_t>(n0));
  for (int i = 0; i < n0; ++i) group[std::size_t(i)] = i;
  auto dropLabel = [&](int drop, int into) {
    for (int& g : group) {
      if (g == drop) g = into;
      if (g > drop) --g;  // the labels after `drop` (the merge target included) move down by one
    }
  };
  // n x n table of predicted increases less their price (a merge pays off below 0); after a merge only the merged
  // label's row and column change.
  std::vector<std::vector<double>> increase(std::size_t(n0), std::vector<double>(std::size_t(n0), 0.0));
  auto fill = [&](int a, int b) {
    const double v = mergeCostIncrease(model.curvature[std::size_t(a)], model.curvature[std::size_t(b)],
                                       twists[std::size_t(a)], twists[std::size_t(b)]);
    const double pair_price = priceFor(price, model.cost[std::size_t(a)], model.cost[std::size_t(b)], config);
    increase[std::size_t(a)][std::size_t(b)] = increase[std::size_t(b)][std::size_t(a)] =
        v + switchingCost(a, b) - pair_price;
  };
  for (int a = 0; a < n0; ++a)
    for (int b = a + 1; b < n0; ++b) fill(a, b);
  for (;;) {
    const int n = int(twists.size());
    double best = std::numeric_limits<double>::infinity();
    int best_a = -1, best_b = -1;
    for (int a = 0; a < n; ++a)
      for (int b = a + 1; b < n; ++b)
        if (increase[std::size_t(a)][std::size_t(b)] < best) {
          best = increase[std::size_t(a)][std::size_t(b)];
          best_a = a;
          best_b = b;
        }
    if (best_a < 0 || !(best < 0.0)) {
      stats.smallest_refused_merge =
          best_a < 0 ? best
                     : best - switchingCost(best_a, best_b) +
                           priceFor(price, model.cost[std::size_t(best_a)], model.cost[std::size_t(best_b)], config);
      break;
    }
    const int keep = support[std::size_t(best_a)] >= support[std::size_t(best_b)] ? best_a : best_b;
    const int drop = keep == best_a ? best_b : best_a;
    const double data_increase = best - switchingCost(keep, drop);  // still less the price
    const Matrix6d H = model.curvature[std::size_t(keep)] + model.curvature[std::size_t(drop)];
    twists[std::size_t(keep)] =
        withRidge(H).ldlt().solve(model.curvature[std::size_t(keep)] * twists[std::size_t(keep)] +
                                  model.curvature[std::size_t(drop)] * twists[std::size_t(drop)]);
    model.curvature[std::size_t(keep)] = H;
    model.gradient[std::size_t(keep)] += model.gradient[std::size_t(drop)];
    // The union pays both costs and the predicted increase (best is the increase less the price).
    model.cost[std::size_t(keep)] +=
        model.cost[std::size_t(drop)] + data_increase +
        priceFor(price, model.cost[std::size_t(keep)], model.cost[std::size_t(drop)], config);
    support[std::size_t(keep)] += support[std::size_t(drop)];
    model.pixels[std::size_t(keep)] += model.pixels[std::size_t(drop)];
    model.pixels.erase(model.pixels.begin() + drop);
    if (lineage) {
      (*lineage)[std::size_t(keep)] = mergedLineage((*lineage)[std::size_t(keep)], (*lineage)[std::size_t(drop)]);
      lineage->erase(lineage->begin() + drop);
    }
    dropLabel(drop, keep);
    support.erase(support.begin() + drop);
    twists.erase(twists.begin() + drop);
    model.curvature.erase(model.curvature.begin() + drop);
    model.gradient.erase(model.gradient.begin() + drop);
    model.cost.erase(model.cost.begin() + drop);
    increase.erase(increase.begin() + drop);
    for (auto& row : increase) row.erase(row.begin() + drop);
    const int kept = keep > drop ? keep - 1 : keep;
    for (int c = 0; c < int(twists.size()); ++c)
      if (c != kept) fill(kept, c);
    ++stats.merged;
  }
  if (remove_small) {
    // Remove labels with too little support (always keep at least one motion label).
    const double min_support = config.min_support_fraction * double(valid_pixels);
    for (int i = int(twists.size()) - 1; i >= 0; --i) {
      if (twists.size() <= 1) break;
      if (support[std::size_t(i)] < min_support) {
        dropLabel(i, -1);
        support.erase(support.begin() + i);
        twists.erase(twists.begin() + i);
        model.curvature.erase(model.curvature.begin() + i);
        model.gradient.erase(model.gradient.begin() + i);
        model.cost.erase(model.cost.begin() + i);
        model.pixels.erase(model.pixels.begin() + i);
        if (lineage) lineage->erase(lineage->begin() + i);
        ++stats.removed;
      }
    }
  }
  if (stats.merged + stats.removed == 0) return stats;
  const int new_count = int(twists.size()) + 1;
  std::vector<int> target(std::size_t(n0) + 1, new_count - 1);
  for (int i = 0; i < n0; ++i)
    if (group[std::size_t(i)] >= 0) target[std::size_t(i)] = group[std::size_t(i)];
  labels.remap(target, new_count);
  return stats;
}

AdaptationStats proposeSplits(LabelStore& labels, std::vector<Vector6d>& twists, bool use_occlusion, int valid_pixels,
                              const Config& config) {
  AdaptationStats stats;
  const int n = labels.labelCount() - 1;
  const int room = config.max_labels - n;
  if (room <= 0 || config.max_splits_per_iteration <= 0) return stats;
  const double min_half = std::max(2.0 * config.min_support_fraction * double(valid_pixels), 32.0);

  // Each candidate's own pixels (u >= 0.5) split at its centroid across its principal axis: the two
  // halves of a segment that holds two parts are, for compact parts, its two ends.
  const std::vector<LabelMoments> moments = labels.ownedMoments();
  std::vector<LabelCut> cuts;
  std::vector<double> owned;
  for (int i = 0; i < n; ++i) {
    const LabelMoments& m = moments[std::size_t(i)];
    if (m.count < 2 * min_half) continue;
    cuts.push_back({i, m.mean(), m.principalAxis()});
    owned.push_back(m.count);
  }
  if (cuts.empty()) return stats;

  // A family of cuts (one per label at most) is tried at once: the second halves become extra labels (hard labels
  // barely interact), and one pass gives every half's cost model at the parent's twist.
  const double price = labelCost(config, valid_pixels);
  struct Candidate {
    double gain;
    LabelCut cut;
    Vector6d stay, leave;  // the halves' Gauss-Newton motions
  };
  std::vector<Candidate> candidates;
  // `family[c]` cuts `cuts[c]`'s parent (the same labels, in the same order); returns the trial.
  auto tryCuts = [&](const std::vector<LabelCut>& family) {
    const int m = int(family.size());
    std::vector<Vector6d> trial_twists = twists;
    for (const LabelCut& c : family) trial_twists.push_back(twists[std::size_t(c.parent)]);
    CutTrial trial = labels.trialCuts(family, trial_twists, use_occlusion, config);
    const LabelCostModel& model = trial.model;
    for (int c = 0; c < m; ++c) {
      const double moved = trial.moved[std::size_t(c)];
      if (moved < min_half || owned[std::size_t(c)] - moved < min_half) continue;
      const int p = family[std::size_t(c)].parent;
      const Matrix6d& H1 = model.curvature[std::size_t(p)];
      const Matrix6d& H2 = model.curvature[std::size_t(n + c)];
      const Vector6d& g1 = model.gradient[std::size_t(p)];
      const Vector6d& g2 = model.gradient[std::size_t(n + c)];
      // What two motions gain over the one best motion for the whole label.
      const double gain = newtonDecrement(H1, g1) + newtonDecrement(H2, g2) - newtonDecrement(H1 + H2, g1 + g2);
      if (gain > priceFor(price, model.cost[std::size_t(p)], model.cost[std::size_t(n + c)], config)) {
        const Vector6d& base = twists[std::size_t(p)];
        candidates.push_back(
            {gain, family[std::size_t(c)], base + gaussNewtonStep(H1, g1), base + gaussNewtonStep(H2, g2)});
      }
    }
    return trial;
  };
  const CutTrial across = tryCuts(cuts);

  // The cuts by the data: each label's pixels that pay more than kSplitCostFactor times its own cost per pixel under
  // its motion (its two halves' cost and pixels at its twist in the first trial: no pass of its own). A label that pays
  // nothing gets an infinite threshold: its cut moves no pixel (and the families stay aligned with `owned`).
  std::vector<LabelCut> by_cost;
  for (std::size_t c = 0; c < cuts.size(); ++c) {
    const std::size_t p = std::size_t(cuts[c].parent), half = std::size_t(n) + c;
    const double cost = across.model.cost[p] + across.model.cost[half];
    const double pixels = across.model.pixels[p] + across.model.pixels[half];
    LabelCut cut;
    cut.parent = cuts[c].parent;
    cut.cost_above =
        cost > 0 ? kSplitCostFactor * cost / std::max(1.0, pixels) : std::numeric_limits<double>::infinity();
    cut.judged_at = twists[p];
    by_cost.push_back(cut);
  }
  tryCuts(by_cost);

  // The best-paying cut of each label, largest gain first; the taken halves become labels n .. n+take-1 (the labels
  // change once).
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const Candidate& a, const Candidate& b) { return a.gain > b.gain; });
  std::vector<LabelCut> taken;
  const int most = std::min(room, config.max_splits_per_iteration);
  for (const Candidate& c : candidates) {
    if (int(taken.size()) >= most) break;
    if (std::any_of(taken.begin(), taken.end(), [&](const LabelCut& t) { return t.parent == c.cut.parent; })) continue;
    taken.push_back(c.cut);
    twists[std::size_t(c.cut.parent)] = c.stay;
    twists.push_back(c.leave);
    ++stats.split;
  }
  if (!taken.empty()) labels.applyCuts(taken, use_occlusion, config);
  return stats;
}

AdaptationStats mergeOcclusionAbsorbers(SolveBackend& backend, std::vector<Vector6d>& twists, int valid_pixels,
                                        const Config& config, std::vector<LabelLineage>* lineage) {
  AdaptationStats stats;
  const int n = int(twists.size());
  if (n != backend.labelCount() - 1)
    throw InputError("mergeOcclusionAbsorbers: " + std::to_string(n) + " twists for " +
                     std::to_string(backend.labelCount() - 1) + " motion labels");
  if (lineage && int(lineage->size()) != n)
    throw InputError("mergeOcclusionAbsorbers: " + std::to_string(lineage->size()) + " lineages for " +
                     std::to_string(n) + " motion labels");
  if (n < 2) {
    backend.updateOcclusion(twists, config);
    return stats;
  }
  const std::vector<double> support = backend.supports();
  const int host = int(std::max_element(support.begin(), support.end()) - support.begin());
  // Each configuration with its own occlusions, as the energy counts them (occluded pixels pay nothing): every other
  // label under the host's motion at once, then the labels under their own motions (whose mask then stays).
  backend.updateOcclusion(std::vector<Vector6d>(std::size_t(n), twists[std::size_t(host)]), config);
  const LabelCostModel under_host =
      backend.costModel(std::vector<Vector6d>(std::size_t(n), twists[std::size_t(host)]), true, config);
  backend.updateOcclusion(twists, config);
  const LabelCostModel own = backend.costModel(twists, true, config);
  const double price = labelCost(config, valid_pixels);
  std::vector<int> target(std::size_t(n) + 1);
  std::vector<Vector6d> kept_twists;
  std::vector<LabelLineage> kept_lineage;
  for (int i = 0; i < n; ++i) {
    const double increase = under_host.cost[std::size_t(i)] - own.cost[std::size_t(i)];
    if (i != host && increase + mergeSwitchingCost(lineage, support, i, host, config) <
                         priceFor(price, own.cost[std::size_t(host)], own.cost[std::size_t(i)], config)) {
      target[std::size_t(i)] = -1;  // into the host, whose index is known below
      ++stats.merged;
      continue;
    }
    target[std::size_t(i)] = int(kept_twists.size());
    kept_twists.push_back(twists[std::size_t(i)]);
    if (lineage) kept_lineage.push_back((*lineage)[std::size_t(i)]);
  }
  if (stats.merged == 0) return stats;
  const int into = target[std::size_t(host)];
  for (int i = 0; i < n; ++i)
    if (target[std::size_t(i)] < 0) {
      target[std::size_t(i)] = into;
      // As a merge in adaptLabelCount.
      if (lineage)
        kept_lineage[std::size_t(into)] = mergedLineage(kept_lineage[std::size_t(into)], (*lineage)[std::size_t(i)]);
    }
  const int kept = int(kept_twists.size());
  target[std::size_t(n)] = kept;  // the outlier label stays last
  backend.remap(target, kept + 1);
  twists.swap(kept_twists);
  if (lineage) lineage->swap(kept_lineage);
  backend.updateOcclusion(twists, config);  // the mask of the merged labels
  return stats;
}

std::vector<LabelCostModel> LabelStore::costModels(const std::vector<std::vector<Vector6d>>& twist_sets,
                                                   bool use_occlusion, const Config& config) {
  std::vector<LabelCostModel> models;
  models.reserve(twist_sets.size());
  for (const std::vector<Vector6d>& twists : twist_sets) models.push_back(costModel(twists, use_occlusion, config));
  return models;
}

std::vector<int> unionBatches(const std::vector<std::vector<int>>& groups) {
  std::vector<int> batch(groups.size(), 0);
  std::vector<std::vector<int>> taken;  // per batch: the labels its groups hold
  for (std::size_t g = 0; g < groups.size(); ++g) {
    int b = 0;
    for (; b < int(taken.size()); ++b) {
      const std::vector<int>& used = taken[std::size_t(b)];
      const bool clash = std::any_of(groups[g].begin(), groups[g].end(),
                                     [&](int i) { return std::find(used.begin(), used.end(), i) != used.end(); });
      if (!clash) break;
    }
    if (b == int(taken.size())) taken.emplace_back();
    taken[std::size_t(b)].insert(taken[std::size_t(b)].end(), groups[g].begin(), groups[g].end());
    batch[g] = b;
  }
  return batch;
}

std::vector<UnionFit> refitUnions(LabelStore& labels, const std::vector<Vector6d>& twists,
                                  const std::vector<std::vector<int>>& groups, const std::vector<Vector6d>& starts,
                                  int iterations, bool use_occlusion, const Config& config) {
  const int n = labels.labelCount() - 1;
  if (int(twists.size()) != n || starts.size() != groups.size())
    throw InputError("refitUnions: " + std::to_string(twists.size()) + " twists for " + std::to_string(n) +
                     " motion labels, " + std::to_string(starts.size()) + " starts for " +
                     std::to_string(groups.size()) + " groups");
  for (std::size_t g = 0; g < groups.size(); ++g) {
    if (groups[g].empty()) throw InputError("refitUnions: group " + std::to_string(g) + " is empty");
    std::vector<bool> member(std::size_t(n), false);
    for (const int i : groups[g]) {
      if (i < 0 || i >= n)
        throw InputError("refitUnions: label " + std::to_string(i) + " outside [0, " + std::to_string(n) + ")");
      if (member[std::size_t(i)])
        throw InputError("refitUnions: label " + std::to_string(i) + " twice in group " + std::to_string(g));
      member[std::size_t(i)] = true;
    }
  }
  const std::vector<int> batch = unionBatches(groups);
  const int batches = groups.empty() ? 0 : *std::max_element(batch.begin(), batch.end()) + 1;
  std::vector<UnionFit> fits(groups.size());
  if (groups.empty()) return fits;
  if (labels.refitUnionsWhereTheSumsAre(twists, groups, batch, starts, iterations, use_occlusion, config, fits))
    return fits;
  std::vector<Vector6d> gradient(groups.size(), Vector6d::Zero());
  std::vector<double> damping(groups.size(), config.motion_damping);
  std::vector<std::vector<Vector6d>> trial(std::size_t(batches), twists);  // one set of twists per batch
  // Sums a pass's models over each group into the fits (the union's cost, H and g at its trial twist).
  auto gather = [&](const std::vector<LabelCostModel>& models, std::vector<UnionFit>& out,
                    std::vector<Vector6d>& out_gradient) {
    for (std::size_t g = 0; g < groups.size(); ++g) {
      const LabelCostModel& model = models[std::size_t(batch[g])];
      UnionFit& f = out[g];
      f.member_cost.assign(groups[g].size(), 0.0);
      f.cost = 0;
      f.pixels = 0;
      f.curvature.setZero();
      out_gradient[g].setZero();
      for (std::size_t m = 0; m < groups[g].size(); ++m) {
        const std::size_t i = std::size_t(groups[g][m]);
        f.member_cost[m] = model.cost[i];
        f.cost += model.cost[i];
        f.pixels += model.pixels[i];
        f.curvature += model.curvature[i];
        out_gradient[g] += model.gradient[i];
      }
    }
  };
  auto setTrial = [&](const std::vector<Vector6d>& group_twists) {
    for (std::size_t g = 0; g < groups.size(); ++g)
      for (const int i : groups[g]) trial[std::size_t(batch[g])][std::size_t(i)] = group_twists[g];
  };
  std::vector<Vector6d> current = starts;
  setTrial(current);
  gather(labels.costModels(trial, use_occlusion, config), fits, gradient);
  for (std::size_t g = 0; g < groups.size(); ++g) fits[g].twist = current[g];
  std::vector<UnionFit> next(groups.size());
  std::vector<Vector6d> next_gradient(groups.size());
  for (int it = 0; it < iterations && !groups.empty(); ++it) {
    std::vector<Vector6d> proposed = current;
    for (std::size_t g = 0; g < groups.size(); ++g) {
      const Matrix6d& H = fits[g].curvature;
      const double scale = std::max(H.diagonal().maxCoeff(), 1e-12);
      const Matrix6d damped = H + (damping[g] + kRidge) * scale * Matrix6d::Identity();
      Vector6d d = -damped.ldlt().solve(gradient[g]);
      d /= std::max(
          {1.0, d.head<3>().norm() / union_refit::kMaxTranslation, d.tail<3>().norm() / union_refit::kMaxRotation});
      // A non-finite step is no step: an infinite trial cost below rejects it and damps harder.
      proposed[g] =
          d.allFinite() ? Vector6d(proposed[g] + d) : Vector6d::Constant(std::numeric_limits<double>::infinity());
    }
    // Groups whose step was not finite keep their twist in the pass and are rejected after it.
    std::vector<bool> finite(groups.size(), true);
    for (std::size_t g = 0; g < groups.size(); ++g)
      if (!proposed[g].allFinite()) {
        finite[g] = false;
        proposed[g] = current[g];
      }
    setTrial(proposed);
    gather(labels.costModels(trial, use_occlusion, config), next, next_gradient);
    for (std::size_t g = 0; g < groups.size(); ++g) {
      if (finite[g] && next[g].cost <= fits[g].cost) {  // accepted: the union's model at the new twist
        const int accepted = fits[g].iterations + 1;
        current[g] = proposed[g];
        fits[g] = next[g];
        fits[g].iterations = accepted;
        gradient[g] = next_gradient[g];
        fits[g].twist = current[g];
        damping[g] = union_refit::dampingAfterAccept(damping[g], config.motion_damping);
      } else {  // rejected: keep the last accepted twist and its model, damp harder
        damping[g] = union_refit::dampingAfterReject(damping[g]);
      }
    }
  }
  return fits;
}

std::vector<UnionFit> refitPairsFromTheBetterMotion(LabelStore& labels, const std::vector<Vector6d>& twists,
                                                    const std::vector<std::vector<int>>& pairs,
                                                    const std::vector<int>& batches,
                                                    const std::vector<double>& own_cost, int iterations,
                                                    bool use_occlusion, const Config& config) {
  const int n = labels.labelCount() - 1;
  if (int(twists.size()) != n || int(own_cost.size()) != n || batches.size() != pairs.size())
    throw InputError("refitPairsFromTheBetterMotion: " + std::to_string(twists.size()) + " twists and " +
                     std::to_string(own_cost.size()) + " costs for " + std::to_string(n) + " motion labels, " +
                     std::to_string(batches.size()) + " batch numbers for " + std::to_string(pairs.size()) + " pairs");
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    const std::vector<int>& pair = pairs[p];
    if (pair.size() != 2 || pair[0] == pair[1] || std::min(pair[0], pair[1]) < 0 || std::max(pair[0], pair[1]) >= n)
      throw InputError("refitPairsFromTheBetterMotion: pair " + std::to_string(p) +
                       " is not two distinct labels in [0, " + std::to_string(n) + ")");
  }
  std::vector<UnionFit> fits;
  if (pairs.empty()) return fits;
  if (labels.refitPairsWhereTheSumsAre(twists, pairs, batches, own_cost, iterations, use_occlusion, config, fits))
    return fits;
  // Each side under the other's motion (one pass per batch): the union's cost at either start.
  std::vector<std::vector<Vector6d>> swapped(std::size_t(*std::max_element(batches.begin(), batches.end()) + 1),
                                             twists);
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    const int a = pairs[p][0], b = pairs[p][1];
    swapped[std::size_t(batches[p])][std::size_t(a)] = twists[std::size_t(b)];
    swapped[std::size_t(batches[p])][std::size_t(b)] = twists[std::size_t(a)];
  }
  const std::vector<LabelCostModel> cross = labels.costModels(swapped, use_occlusion, config);
  std::vector<Vector6d> starts;
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    const int a = pairs[p][0], b = pairs[p][1];
    const LabelCostModel& other = cross[std::size_t(batches[p])];
    const double at_a = own_cost[std::size_t(a)] + other.cost[std::size_t(b)];
    const double at_b = other.cost[std::size_t(a)] + own_cost[std::size_t(b)];
    starts.push_back(at_a <= at_b ? twists[std::size_t(a)] : twists[std::size_t(b)]);
  }
  return refitUnions(labels, twists, pairs, starts, iterations, use_occlusion, config);
}

LabelLineage mergedLineage(const LabelLineage& keep, const LabelLineage& drop) {
  return keep.carried || !drop.carried ? keep : drop;
}

bool movedApartBefore(const LabelLineage& a, const LabelLineage& b, double displacement) {
  if (!a.carried || !b.carried || displacement <= 0) return false;
  const Eigen::Matrix4d Ta = se3Exp(a.previous_twist), Tb = se3Exp(b.previous_twist);
  auto apart = [&](const Eigen::Vector3d& c) {
    const Eigen::Vector3d pa = Ta.topLeftCorner<3, 3>() * c + Ta.topRightCorner<3, 1>();
    const Eigen::Vector3d pb = Tb.topLeftCorner<3, 3>() * c + Tb.topRightCorner<3, 1>();
    return (pa - pb).norm();
  };
  return std::max(apart(a.previous_centroid), apart(b.previous_centroid)) > displacement;
}

bool oneMotionExplains(const MergeEvidence& e, double own_tolerance, double noise_tolerance) {
  if (own_tolerance <= 0 || noise_tolerance <= 0) return false;
  const double noise = std::max(0.0, e.noise_per_pixel);
  auto side = [&](double increase, double own, double pixels) {
    return increase <= own_tolerance * std::max(0.0, own) && increase <= noise_tolerance * noise * pixels;
  };
  return side(e.increase_a, e.own_a, e.pixels_a) && side(e.increase_b, e.own_b, e.pixels_b);
}

AdaptationStats mergeWhereOneMotionExplains(LabelStore& labels, std::vector<Vector6d>& twists, int valid_pixels,
                                            bool use_occlusion, const Config& config,
                                            std::vector<LabelLineage>* lineage, const LabelCostModel* own_model) {
  AdaptationStats stats;
  if (int(twists.size()) != labels.labelCount() - 1)
    throw InputError("mergeWhereOneMotionExplains: " + std::to_string(twists.size()) + " twists for " +
                     std::to_string(labels.labelCount() - 1) + " motion labels");
  if (lineage && lineage->size() != twists.size())
    throw InputError("mergeWhereOneMotionExplains: " + std::to_string(lineage->size()) + " lineages for " +
                     std::to_string(twists.size()) + " motion labels");
  if (config.merge_refit_tolerance <= 0 || config.merge_refit_noise_tolerance <= 0) return stats;
  // Batches of disjoint pairs tested per round: what fills about one pass over kMergeRoundPixels (on the GPU the
  // batches of a round share one launch, nearly free while the label level is small).
  const int batches_per_round = std::max(1, int(kMergeRoundPixels / std::max(1, valid_pixels)));
  // Pairs refused since the labels last changed: a round tests the others.
  std::vector<std::pair<int, int>> refused;
  LabelCostModel own;  // the labels' models under their own motions; kept while no merge changes the labels
  bool own_current = false;
  if (own_model) {
    if (own_model->cost.size() != twists.size() || own_model->pixels.size() != twists.size())
      throw InputError("mergeWhereOneMotionExplains: a cost model of " + std::to_string(own_model->cost.size()) +
                       " labels for " + std::to_string(twists.size()) + " motion labels");
    own = *own_model;
    own_current = true;
  }
  for (;;) {
    const int n = int(twists.size());
    if (n < 2) break;
    if (!own_current) own = labels.costModel(twists, use_occlusion, config);
    own_current = true;
    // The data term's noise level: what a pixel of the widest label (usually the static world) pays under its own
    // motion: sensor noise, blur, rolling shutter, colour and depth out of step, all that one rigid motion leaves.
    const int widest = int(std::max_element(own.pixels.begin(), own.pixels.end()) - own.pixels.begin());
    const double noise = own.cost[std::size_t(widest)] / std::max(1.0, own.pixels[std::size_t(widest)]);
    // What sensor effects make a rigid thing look non-rigid grows with its extent in the image: the widest label is
    // judged with merge_refit_tolerance, two smaller ones (parts, which must stay apart when they move) with
    // merge_refit_tolerance_parts. So are two labels a stream kept apart in the previous pair: they were judged apart
    // there, and only a motion that now explains both closely undoes that.
    auto bothCarried = [&](int a, int b) {
      return lineage && (*lineage)[std::size_t(a)].carried && (*lineage)[std::size_t(b)].carried;
    };
    auto ownTolerance = [&](int a, int b) {
      return (a == widest || b == widest) && !bothCarried(a, b) ? config.merge_refit_tolerance
                                                                : config.merge_refit_tolerance_parts;
    };
    // Two carried labels whose previous motions moved them apart: a part at the turn of its motion (momentarily at
    // rest) is not merged, so it keeps its segment and id; after a pair at rest it is tested like any other.
    auto deferred = [&](int a, int b) {
      return lineage &&
             movedApartBefore((*lineage)[std::size_t(a)], (*lineage)[std::size_t(b)], config.merge_memory_displacement);
    };
    // Candidates, most alike first: the quadratic model's predicted increase against what the pair may pay. A pair
    // the model prices far beyond that (a distinct motion) is not refitted.
    std::vector<std::pair<double, std::pair<int, int>>> candidates;
    for (int a = 0; a < n; ++a)
      for (int b = a + 1; b < n; ++b) {
        const double allowed =
            std::min(ownTolerance(a, b) * std::max(0.0, std::min(own.cost[std::size_t(a)], own.cost[std::size_t(b)])),
                     config.merge_refit_noise_tolerance * noise *
                         std::min(own.pixels[std::size_t(a)], own.pixels[std::size_t(b)]));
        const double predicted = mergeCostIncrease(own.curvature[std::size_t(a)], own.curvature[std::size_t(b)],
                                                   twists[std::size_t(a)], twists[std::size_t(b)]);
        const double ratio = predicted / std::max(allowed, 1e-9);
        if (ratio < kRefitCandidateRatio && !deferred(a, b) &&
            std::find(refused.begin(), refused.end(), std::make_pair(a, b)) == refused.end())
          candidates.push_back({ratio, {a, b}});
      }
    if (candidates.empty()) break;
    std::sort(candidates.begin(), candidates.end());
    // The candidates of the round's first batches_per_round batches (unionBatches: disjoint pairs share a pass, the
    // dominant label takes part in one pair per batch), most alike first.
    std::vector<std::vector<int>> all;
    for (const auto& c : candidates) all.push_back({c.second.first, c.second.second});
    const std::vector<int> all_batches = unionBatches(all);
    std::vector<std::vector<int>> groups;
    std::vector<int> batch;
    for (std::size_t p = 0; p < all.size(); ++p)
      if (all_batches[p] < batches_per_round) {
        groups.push_back(all[p]);
        batch.push_back(all_batches[p]);
      }
    const std::vector<UnionFit> fits = refitPairsFromTheBetterMotion(
        labels, twists, groups, batch, own.cost, config.merge_refit_iterations, use_occlusion, config);
    ++stats.rounds;
    stats.pairs_tested += int(groups.size());
    // Merges of this round, most alike first, each label in one at most: each pair into its larger label, which takes
    // the union's motion. An explained pair with a label already merged is tested again on the merged labels.
    std::vector<int> group(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) group[std::size_t(i)] = i;
    std::vector<bool> used(std::size_t(n), false);
    std::vector<Vector6d> merged_twists = twists;
    int merged = 0;
    for (std::size_t p = 0; p < groups.size(); ++p) {
      const int a = groups[p][0], b = groups[p][1];
      const UnionFit& f = fits[p];
      MergeEvidence evidence;
      evidence.own_a = own.cost[std::size_t(a)];
      evidence.own_b = own.cost[std::size_t(b)];
      evidence.increase_a = f.member_cost[0] - evidence.own_a;
      evidence.increase_b = f.member_cost[1] - evidence.own_b;
      evidence.pixels_a = own.pixels[std::size_t(a)];
      evidence.pixels_b = own.pixels[std::size_t(b)];
      evidence.noise_per_pixel = noise;
      if (!oneMotionExplains(evidence, ownTolerance(a, b), config.merge_refit_noise_tolerance)) {
        refused.push_back({a, b});
        continue;
      }
      if (used[std::size_t(a)] || used[std::size_t(b)]) continue;
      used[std::size_t(a)] = used[std::size_t(b)] = true;
      const int keep = own.pixels[std::size_t(a)] >= own.pixels[std::size_t(b)] ? a : b;
      const int drop = keep == a ? b : a;
      group[std::size_t(drop)] = keep;
      merged_twists[std::size_t(keep)] = f.twist;
      if (lineage)
        (*lineage)[std::size_t(keep)] = mergedLineage((*lineage)[std::size_t(keep)], (*lineage)[std::size_t(drop)]);
      ++merged;
    }
    if (merged == 0) continue;  // the same labels: the refused pairs stay refused, the others get their turn
    refused.clear();
    own_current = false;
    std::vector<int> target(std::size_t(n) + 1);
    std::vector<Vector6d> kept_twists;
    std::vector<LabelLineage> kept_lineage;
    for (int i = 0; i < n; ++i) {
      if (group[std::size_t(i)] != i) continue;
      target[std::size_t(i)] = int(kept_twists.size());
      kept_twists.push_back(merged_twists[std::size_t(i)]);
      if (lineage) kept_lineage.push_back((*lineage)[std::size_t(i)]);
    }
    for (int i = 0; i < n; ++i)
      if (group[std::size_t(i)] != i) target[std::size_t(i)] = target[std::size_t(group[std::size_t(i)])];
    const int kept = int(kept_twists.size());
    target[std::size_t(n)] = kept;  // the outlier label stays last
    labels.remap(target, kept + 1);
    twists.swap(kept_twists);
    if (lineage) lineage->swap(kept_lineage);
    stats.merged += merged;
  }
  return stats;
}

HostLabelStore::HostLabelStore(SoftLabels& u, const PyramidLevel& frame1, const PyramidLevel& frame2,
                               const ImageU8* occluded, MotionAccumulator* accumulator)
    : u_(u), frame1_(frame1), frame2_(frame2), occluded_(occluded), accumulator_(accumulator) {
  if (!accumulator_) {
    own_accumulator_ = makeCpuMotionAccumulator();
    accumulator_ = own_accumulator_.get();
  }
}

std::vector<double> HostLabelStore::supports() {
  std::vector<double> out(std::size_t(std::max(0, u_.count - 1)));
  for (int i = 0; i + 1 < u_.count; ++i) out[std::size_t(i)] = u_.support(i);
  return out;
}

void HostLabelStore::remap(const std::vector<int>& target, int new_count) {
  validateRemap(target, u_.count, new_count);
  SoftLabels out(u_.width, u_.height, new_count, 0.f);
  const std::size_t plane = u_.planeSize();
  for (int i = 0; i < u_.count; ++i) {
    const float* src = u_.plane(i);
    float* dst = out.plane(target[std::size_t(i)]);
    for (std::size_t k = 0; k < plane; ++k) dst[k] += src[k];
  }
  u_ = std::move(out);
}

std::vector<LabelMoments> HostLabelStore::ownedMoments() {
  const int n = u_.count - 1;
  std::vector<LabelMoments> out(std::size_t(std::max(0, n)));
  const std::size_t plane = u_.planeSize();
  const ImageF& points = frame1_.points;
  for (int i = 0; i < n; ++i) {
    const float* ui = u_.plane(i);
    LabelMoments& m = out[std::size_t(i)];
    for (std::size_t k = 0; k < plane; ++k) {
      if (ui[k] < 0.5f || !std::isfinite(points.data[k * 3 + 2])) continue;
      m.add(Eigen::Vector3d(points.data[k * 3], points.data[k * 3 + 1], points.data[k * 3 + 2]));
    }
  }
  return out;
}

SoftLabels HostLabelStore::withCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config,
                                    std::vector<double>& moved) const {
  const int n = u_.count - 1, m = int(cuts.size());
  for (const LabelCut& c : cuts)
    if (c.parent < 0 || c.parent >= n)
      throw InputError("label cut: parent " + std::to_string(c.parent) + " is not a motion label (count " +
                       std::to_string(u_.count) + ")");
  const std::size_t plane = u_.planeSize();
  SoftLabels grown(u_.width, u_.height, u_.count + m, 0.f);
  for (int i = 0; i < n; ++i) std::copy_n(u_.plane(i), plane, grown.plane(i));
  std::copy_n(u_.plane(u_.outlier()), plane, grown.plane(grown.outlier()));
  const ImageF& points = frame1_.points;
  moved.assign(std::size_t(m), 0.0);
  // The cuts by the data: each one's data costs under its own twist, as one plane of a label problem.
  std::vector<Vector6d> judged_at;
  std::vector<int> cost_plane(std::size_t(m), -1);
  for (int c = 0; c < m; ++c)
    if (cuts[std::size_t(c)].cost_above > 0) {
      cost_plane[std::size_t(c)] = int(judged_at.size());
      judged_at.push_back(cuts[std::size_t(c)].judged_at);
    }
  LabelProblem costs;
  if (!judged_at.empty())
    computeDataCosts(frame1_, frame2_, judged_at, use_occlusion ? occluded_ : nullptr, config, costs);
  for (int c = 0; c < m; ++c) {
    const LabelCut& cut = cuts[std::size_t(c)];
    float* from = grown.plane(cut.parent);
    float* to = grown.plane(n + c);
    const float* cost = cost_plane[std::size_t(c)] < 0
                            ? nullptr
                            : costs.data_cost.data() + std::size_t(cost_plane[std::size_t(c)]) * plane;
    for (std::size_t k = 0; k < plane; ++k) {
      if (from[k] < 0.5f || !std::isfinite(points.data[k * 3 + 2])) continue;
      if (cost) {
        if (!(double(cost[k]) > cut.cost_above)) continue;
      } else {
        const Eigen::Vector3d P(points.data[k * 3], points.data[k * 3 + 1], points.data[k * 3 + 2]);
        if ((P - cut.centre).dot(cut.axis) <= 0) continue;
      }
      to[k] = from[k];
      from[k] = 0.f;
      ++moved[std::size_t(c)];
    }
  }
  return grown;
}

CutTrial HostLabelStore::trialCuts(const std::vector<LabelCut>& cuts, const std::vector<Vector6d>& twists,
                                   bool use_occlusion, const Config& config) {
  CutTrial trial;
  const SoftLabels grown = withCuts(cuts, use_occlusion, config, trial.moved);
  trial.model =
      labelCostModel(frame1_, frame2_, grown, use_occlusion ? occluded_ : nullptr, twists, config, *accumulator_);
  return trial;
}

void HostLabelStore::applyCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) {
  std::vector<double> moved;
  u_ = withCuts(cuts, use_occlusion, config, moved);
}

LabelCostModel HostLabelStore::costModel(const std::vector<Vector6d>& twists, bool use_occlusion,
                                         const Config& config) {
  return labelCostModel(frame1_, frame2_, u_, use_occlusion ? occluded_ : nullptr, twists, config, *accumulator_);
}

}  // namespace mc_flow
