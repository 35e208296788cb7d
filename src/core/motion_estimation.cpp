// Motion step: all labels' twists solved jointly by IRLS with the Cauchy M-estimator (eqs. 8-10) under
// the motion-interpolation model (eq. 2). A pixel's residual uses xi_bar(x) = sum_i w_i(x) xi_i, so its
// Jacobian row for label i is w_i(x) J(x) and the normal equations couple labels that share pixels.
#include "mc_flow/core/motion_estimation.h"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <numeric>
#include <memory>
#include <string>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/core/motion_estimation_pixel.h"
#include "mc_flow/core/motion_step_control.h"
#include "mc_flow/core/sampling.h"
#include "mc_flow/core/scene_flow.h"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace mc_flow {

namespace {

using Vector6f = Eigen::Matrix<float, 6, 1>;
using RowMajor6f = Eigen::Matrix<float, 6, 6, Eigen::RowMajor>;
using RowMajor34f = Eigen::Matrix<float, 3, 4, Eigen::RowMajor>;

// A pixel warped out of view (or behind the camera) costs as much as a residual of 10 Cauchy scales in
// both kinds: otherwise a label could lower its cost by pushing its pixels out of the image.
constexpr double kOutOfViewResidualScales = 10.0;

class CpuMotionAccumulator final : public MotionAccumulator {
 public:
  std::string name() const override { return "cpu"; }

  void setLevel(const PyramidLevel& frame1, const PyramidLevel& frame2, const SoftLabels& labels,
                const ImageU8* occluded, const Config& config) override {
    frame1_ = &frame1;
    frame2_ = &frame2;
    labels_ = &labels;
    occluded_ = occluded;
    config_ = config;
  }

  void accumulate(const std::vector<Vector6d>& twists, MotionNormalEquations& total) override {
    const PyramidLevel& frame1 = *frame1_;
    const PyramidLevel& frame2 = *frame2_;
    const SoftLabels& labels = *labels_;
    const ImageU8* occluded = occluded_;
    const int W = frame1.points.width, H = frame1.points.height;
    const int motion_labels = labels.count - 1;
    const std::size_t plane = std::size_t(W) * H;
    const Intrinsics& K = frame2.intrinsics;
    const float fx = float(K.fx), fy = float(K.fy), cx = float(K.cx), cy = float(K.cy);
    const float cI = float(config_.cauchy_c_intensity), cZ = float(config_.cauchy_c_depth);
    const float depth_noise_reference = float(config_.depth_noise_reference);
    const float alpha = float(config_.alpha), min_weight = float(config_.min_label_weight);
    const double out_of_view_cost = motionOutOfViewCost(config_);
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    accumulators_.resize(static_cast<std::size_t>(threads));

    std::vector<RowMajor34f> transforms(static_cast<std::size_t>(motion_labels));
    // Additive twist increments act on the warp through the left Jacobian: exp(xi + d) = exp(J_l d) exp(xi).
    std::vector<RowMajor6f> left_jacobians(static_cast<std::size_t>(motion_labels));
    for (int i = 0; i < motion_labels; ++i) {
      transforms[std::size_t(i)] = se3Exp(twists[std::size_t(i)]).topRows<3>().cast<float>();
      left_jacobians[std::size_t(i)] = se3LeftJacobian(twists[std::size_t(i)]).cast<float>();
    }
    for (auto& a : accumulators_) a.reset(motion_labels);

#pragma omp parallel
    {
      int thread = 0;
#ifdef _OPENMP
      thread = omp_get_thread_num();
#endif
      MotionNormalEquations& acc = accumulators_[std::size_t(thread)];
      std::vector<int> active(static_cast<std::size_t>(motion_labels));
      std::vector<float> weights(static_cast<std::size_t>(motion_labels));
      // Static schedule: each thread always sums the same rows, and the per-thread sums are added in thread
      // order below, so the result is the same from run to run for a given thread count.
#pragma omp for schedule(static)
      for (int y = 0; y < H; ++y) {
        for (int x = 0; x < W; ++x) {
          const std::size_t idx = std::size_t(y) * W + x;
          const float P[3] = {frame1.points(x, y, 0), frame1.points(x, y, 1), frame1.points(x, y, 2)};
          if (!std::isfinite(P[2])) continue;
          if (occluded && occluded->data[idx]) continue;
          // Interpolation weights over the motion labels; the outlier share scales the pixel down.
          float mass = 0.f;
          for (int i = 0; i < motion_labels; ++i) mass += labels.data[i * plane + idx];
          if (!motion_pixel::usableMass(mass)) continue;
          int n_active = 0;
          float active_mass = 0.f;
          for (int i = 0; i < motion_labels; ++i) {
            const float w = motion_pixel::labelShare(labels.data[i * plane + idx], mass);
            if (w >= min_weight) {
              active[std::size_t(n_active)] = i;
              weights[std::size_t(n_active)] = w;
              active_mass += w;
              ++n_active;
            }
          }
          if (n_active == 0) continue;
          for (int k = 0; k < n_active; ++k) weights[std::size_t(k)] /= active_mass;

          float P2[3];
          RowMajor34f blended_transform;
          RowMajor6f blended_jacobian;
          const RowMajor34f* transform = &transforms[std::size_t(active[0])];
          const RowMajor6f* left_jacobian = &left_jacobians[std::size_t(active[0])];
          if (n_active > 1) {
            Vector6d xi_bar = Vector6d::Zero();
            for (int k = 0; k < n_active; ++k)
              xi_bar += double(weights[std::size_t(k)]) * twists[std::size_t(active[std::size_t(k)])];
            blended_transform = se3Exp(xi_bar).topRows<3>().cast<float>();
            blended_jacobian = se3LeftJacobian(xi_bar).cast<float>();
            transform = &blended_transform;
            left_jacobian = &blended_jacobian;
          }
          transformPoint(transform->data(), P, P2);
          motion_pixel::Projection proj;
          const bool in_view = motion_pixel::project(P2, fx, fy, cx, cy, W, H, proj);
          const float u = proj.u, v = proj.v;
          float I2, gIx = 0.f, gIy = 0.f;
          if (!in_view || !sampleBilinear(frame2.intensity, u, v, 0, I2)) {
            for (int a = 0; a < n_active; ++a)
              acc.label_cost(active[std::size_t(a)]) += mass * weights[std::size_t(a)] * out_of_view_cost;
            acc.cost += mass * out_of_view_cost;
            continue;
          }
          sampleBilinear(frame2.intensity_grad, u, v, 0, gIx);
          sampleBilinear(frame2.intensity_grad, u, v, 1, gIy);
          const float rI = subRn(frame1.intensity(x, y), I2);
          float row[3];
          Vector6f JI;
          motion_pixel::intensityRow(proj, gIx, gIy, row);
          motion_pixel::residualJacobian(P2, row, left_jacobian->data(), JI.data());
          const float wI = motion_pixel::cauchyWeight(1.f, cI, rI);
          Eigen::Matrix<float, 6, 6> Hp = wI * JI * JI.transpose();
          Vector6f gp = wI * rI * JI;
          double cost = motion_pixel::cauchyCost(cI, rI);

          float Z2;
          if (sampleDepthBilinearSmooth(frame2.depth, u, v, motion_pixel::kDepthEdgeJump, Z2)) {
            float gZx = 0.f, gZy = 0.f;
            sampleBilinear(frame2.depth_grad, u, v, 0, gZx);
            sampleBilinear(frame2.depth_grad, u, v, 1, gZy);
            const float rZ = subRn(P2[2], Z2);
            Vector6f JZ;
            motion_pixel::depthRow(proj, gZx, gZy, row);
            motion_pixel::residualJacobian(P2, row, left_jacobian->data(), JZ.data());
            const float cZ_here = motion_pixel::depthCauchyScale(cZ, depth_noise_reference, Z2);
            const float wZ = motion_pixel::cauchyWeight(alpha, cZ_here, rZ);
            Hp += wZ * JZ * JZ.transpose();
            gp += wZ * rZ * JZ;
            cost += mulRn(alpha, motion_pixel::cauchyCost(cZ_here, rZ));
          } else {
            cost += motion_pixel::missingDepthCost(alpha);
          }
          const Eigen::Matrix<double, 6, 6> Hd = (mass * Hp).cast<double>();
          const Vector6d gd = (mass * gp).cast<double>();
          for (int a = 0; a < n_active; ++a) {
            const int ia = active[std::size_t(a)];
            const double wa = weights[std::size_t(a)];
            acc.g.segment<6>(6 * ia) += wa * gd;
            acc.label_cost(ia) += wa * mass * cost;
            acc.label_pixels(ia) += wa * mass;
            for (int b = 0; b < n_active; ++b) {
              const int ib = active[std::size_t(b)];
              acc.H.block<6, 6>(6 * ia, 6 * ib) += (wa * weights[std::size_t(b)]) * Hd;
            }
          }
          acc.cost += mass * cost;
          ++acc.pixels;
        }
      }
    }
    total = accumulators_[0];
    for (std::size_t t = 1; t < accumulators_.size(); ++t) total.add(accumulators_[t]);
  }

 private:
  const PyramidLevel* frame1_ = nullptr;
  const PyramidLevel* frame2_ = nullptr;
  const SoftLabels* labels_ = nullptr;
  const ImageU8* occluded_ = nullptr;
  Config config_;
  std::vector<MotionNormalEquations> accumulators_;  // one per OpenMP thread, reused across iterations
};

}  // namespace

void MotionNormalEquations::reset(int labels) {
  H.setZero(6 * labels, 6 * labels);
  g.setZero(6 * labels);
  label_cost.setZero(labels);
  label_pixels.setZero(labels);
  cost = 0;
  pixels = 0;
}

void MotionNormalEquations::add(const MotionNormalEquations& other) {
  H += other.H;
  g += other.g;
  label_cost += other.label_cost;
  label_pixels += other.label_pixels;
  cost += other.cost;
  pixels += other.pixels;
}

std::string toString(MotionStop stop) {
  switch (stop) {
    case MotionStop::NoLabels: return "no_labels";
    case MotionStop::IterationLimit: return "iteration_limit";
    case MotionStop::SmallUpdate: return "small_update";
    case MotionStop::TooFewPixels: return "too_few_pixels";
    case MotionStop::SolveFailed: return "solve_failed";
  }
  return "unknown(" + std::to_string(int(stop)) + ")";
}

double motionOutOfViewCost(const Config& config) {
  return (1.0 + config.alpha) * std::log1p(kOutOfViewResidualScales * kOutOfViewResidualScales);
}

std::unique_ptr<MotionAccumulator> makeCpuMotionAccumulator() { return std::make_unique<CpuMotionAccumulator>(); }

#ifndef MCFLOW_HAVE_CUDA
std::unique_ptr<MotionAccumulator> makeCudaMotionAccumulator() {
  throw BackendError(
      "CUDA motion step requested but this build has no CUDA (built without nvcc or MCFLOW_WITH_CUDA=OFF)");
}
#endif

MotionLevelStats estimateMotionsAtLevel(const PyramidLevel& frame1, const PyramidLevel& frame2,
                                        const SoftLabels& labels, const ImageU8* occluded,
                                        std::vector<Vector6d>& twists, const Config& config,
                                        MotionAccumulator* accumulator) {
  const int motion_labels = labels.count - 1;
  if (labels.count < 1 || int(twists.size()) != motion_labels)
    throw InputError("estimateMotionsAtLevel: " + std::to_string(twists.size()) + " twists for " +
                     std::to_string(labels.count) + " label planes (expected one twist per motion label, count - 1)");
  if (motion_labels == 0) return MotionLevelStats{};  // stop = NoLabels: only the outlier label
  std::unique_ptr<MotionAccumulator> own;
  if (!accumulator) {
    own = makeCpuMotionAccumulator();
    accumulator = own.get();
  }
  accumulator->setLevel(frame1, frame2, labels, occluded, config);
  return estimateMotionsWith(*accumulator, twists, config);
}

int solveCoupledBlocks(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, Eigen::VectorXd& delta,
                       double min_coupling) {
  const int n = int(g.size() / 6);
  if (H.rows() != 6 * n || H.cols() != 6 * n || g.size() != 6 * n)
    throw InputError("solveCoupledBlocks: H is " + std::to_string(H.rows()) + "x" + std::to_string(H.cols()) +
                     " and g has " + std::to_string(g.size()) + " entries (expected 6n x 6n and 6n)");
  using Block = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;
  std::vector<std::array<double, 21>> factor(static_cast<std::size_t>(n));  // of each damped diagonal block
  if (min_coupling > 0.0)
    for (int i = 0; i < n; ++i) {
      const Block A = H.block<6, 6>(6 * i, 6 * i);
      choleskyLower6(A.data(), factor[std::size_t(i)].data());
    }
  auto coupled = [&](int a, int b) {
    const Block pair = H.block<6, 6>(6 * a, 6 * b);
    const bool any_entry = pair.cwiseAbs().maxCoeff() > 0.0;
    const double strength =
        any_entry && min_coupling > 0.0
            ? motionCouplingStrength(factor[std::size_t(a)].data(), pair.data(), factor[std::size_t(b)].data())
            : 0.0;
    return motionLabelsCoupled(strength, any_entry, min_coupling);
  };
  // Groups of coupled labels: union-find over the couplings at least min_coupling strong.
  std::vector<int> parent(static_cast<std::size_t>(n));
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&parent](int i) {
    while (parent[std::size_t(i)] != i) i = parent[std::size_t(i)] = parent[std::size_t(parent[std::size_t(i)])];
    return i;
  };
  for (int a = 0; a < n; ++a)
    for (int b = a + 1; b < n; ++b)
      if (coupled(a, b)) parent[std::size_t(root(b))] = root(a);
  // The labels grouped by root (groups in the order of their roots, labels ascending within a group).
  std::vector<int> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  for (int i = 0; i < n; ++i) parent[std::size_t(i)] = root(i);
  std::stable_sort(order.begin(), order.end(),
                   [&parent](int a, int b) { return parent[std::size_t(a)] < parent[std::size_t(b)]; });
  delta.resize(6 * n);
  int largest = 0;
  for (std::size_t begin = 0, end = 0; begin < order.size(); begin = end) {
    while (end < order.size() && parent[std::size_t(order[end])] == parent[std::size_t(order[begin])]) ++end;
    const int* group = order.data() + begin;
    const int labels = int(end - begin), m = 6 * labels;
    largest = std::max(largest, labels);
    Eigen::MatrixXd A(m, m);
    Eigen::VectorXd b(m);
    for (int r = 0; r < labels; ++r) {
      b.segment<6>(6 * r) = -g.segment<6>(6 * group[r]);
      for (int c = 0; c < labels; ++c) A.block<6, 6>(6 * r, 6 * c) = H.block<6, 6>(6 * group[r], 6 * group[c]);
    }
    const Eigen::VectorXd x = A.ldlt().solve(b);
    for (int r = 0; r < labels; ++r) delta.segment<6>(6 * group[r]) = x.segment<6>(6 * r);
  }
  return largest;
}

MotionLevelStats estimateMotionsWith(MotionAccumulator& bound_accumulator, std::vector<Vector6d>& twists,
                                     const Config& config) {
  MotionLevelStats stats;
  const int motion_labels = int(twists.size());
  if (motion_labels <= 0) return stats;
  MotionAccumulator* accumulator = &bound_accumulator;
  MotionNormalEquations total;

  // A device-resident accumulator runs the whole loop where its data lives (the same step control, one
  // download per level instead of one per iteration).
  if (accumulator->iterateLevel(twists, config, stats)) return stats;

  // Per-label Levenberg-Marquardt with backtracking (motion_step_control.h): a label whose cost rose after its last
  // update goes back half way and is damped harder; labels are nearly decoupled (most pixels have one label), so each
  // gets its own trust region.
  std::vector<MotionLabelControl> control(static_cast<std::size_t>(motion_labels));
  for (int i = 0; i < motion_labels; ++i)
    startMotionLabelControl(twists[std::size_t(i)].data(), config.motion_damping, control[std::size_t(i)]);

  using Clock = std::chrono::steady_clock;
  auto millisecondsSince = [](Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
  };
  const auto level_start = Clock::now();
  Eigen::VectorXd delta;
  stats.stop = MotionStop::IterationLimit;
  for (int iteration = 0; iteration < config.motion_iterations_per_level; ++iteration) {
    const auto accumulate_start = Clock::now();
    accumulator->accumulate(twists, total);
    stats.accumulate_ms += millisecondsSince(accumulate_start);
    if (iteration == 0) stats.cost_before = total.cost;
    stats.cost_after = total.cost;
    stats.pixels_used = total.pixels;
    stats.iterations = iteration + 1;
    if (total.pixels < 6) {
      stats.stop = MotionStop::TooFewPixels;
      break;
    }

    // Accept or undo each label's last step; undone and unsupported labels get a zero update now.
    std::vector<bool> frozen(static_cast<std::size_t>(motion_labels), false);
    for (int i = 0; i < motion_labels; ++i)
      frozen[std::size_t(i)] =
          controlMotionLabel(total.label_cost(i), total.label_pixels(i), config.motion_min_label_pixels,
                             config.motion_damping, twists[std::size_t(i)].data(), control[std::size_t(i)]);
    // The last iteration only checks the previous step: an unchecked step could leave a label worse off.
    if (iteration + 1 == config.motion_iterations_per_level) break;
    for (int i = 0; i < motion_labels; ++i) {
      if (frozen[std::size_t(i)]) {
        total.H.middleRows(6 * i, 6).setZero();
        total.H.middleCols(6 * i, 6).setZero();
        total.H.block<6, 6>(6 * i, 6 * i).setIdentity();
        total.g.segment<6>(6 * i).setZero();
        continue;
      }
      const double block_max = total.H.block<6, 6>(6 * i, 6 * i).diagonal().maxCoeff();
      for (int d = 6 * i; d < 6 * i + 6; ++d)
        total.H(d, d) = dampedDiagonal(total.H(d, d), control[std::size_t(i)].damping, block_max);
    }
    stats.largest_block =
        std::max(stats.largest_block, solveCoupledBlocks(total.H, total.g, delta, config.motion_min_coupling));
    if (!delta.allFinite()) {
      stats.stop = MotionStop::SolveFailed;
      break;
    }
    double largest = 0;
    for (int i = 0; i < motion_labels; ++i) {
      Vector6d d = delta.segment<6>(6 * i);
      largest = std::max(largest, limitMotionStep(d.data()));
      twists[std::size_t(i)] += d;
    }
    if (largest < config.motion_min_update) {
      stats.stop = MotionStop::SmallUpdate;
      break;
    }
  }
  // A backtracked step that was not evaluated any more is dropped: return the last accepted twists.
  for (int i = 0; i < motion_labels; ++i)
    for (int k = 0; k < 6; ++k) twists[std::size_t(i)](k) = control[std::size_t(i)].accepted_twist[k];
  stats.solve_ms = millisecondsSince(level_start) - stats.accumulate_ms;
  return stats;
}

}  // namespace mc_flow
