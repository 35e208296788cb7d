// Label step on the CPU: data costs (eq. 5), geometric weights (eq. 11) and the diagonally
// preconditioned primal-dual iteration. The derivation of every step is in docs/ALGORITHM.md.
#include "mc_flow/core/label_optimization.h"

#include <algorithm>
#include <cmath>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_step_pixel.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/sampling.h"
#include "mc_flow/core/simplex_projection.h"
#include "mc_flow/core/solve_backend.h"

namespace mc_flow {

void projectOntoSimplex(float* v, int n) { projectOntoSimplexStrided(v, n, 1); }

void geometricWeights(const PyramidLevel& frame1, double min_weight, ImageF& weight_x, ImageF& weight_y) {
  const ImageF& P = frame1.points;
  const int W = P.width, H = P.height;
  weight_x = ImageF(W, H, 1, 0.f);
  weight_y = ImageF(W, H, 1, 0.f);
  const float fmean = label_pixel::geometricWeightFocal(frame1.intrinsics);
  const float wmin = float(min_weight);
  auto weight = [&](int x0, int y0, int x1, int y1) {
    return label_pixel::geometricWeight(P(x0, y0, 0), P(x0, y0, 1), P(x0, y0, 2), P(x1, y1, 0), P(x1, y1, 1),
                                        P(x1, y1, 2), fmean, wmin);
  };
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      if (x + 1 < W) weight_x(x, y) = weight(x, y, x + 1, y);
      if (y + 1 < H) weight_y(x, y) = weight(x, y, x, y + 1);
    }
  }
}

void computeDataCosts(const PyramidLevel& frame1, const PyramidLevel& frame2, const std::vector<Vector6d>& twists,
                      const ImageU8* occluded, const Config& config, LabelProblem& problem) {
  const int W = frame1.points.width, H = frame1.points.height;
  const int motion_labels = int(twists.size());
  const int n = motion_labels + 1;
  problem.width = W;
  problem.height = H;
  problem.count = n;
  problem.regularizer = config.regularizer;
  problem.lambda = config.lambda();
  problem.data_cost.assign(std::size_t(W) * H * n, 0.f);
  problem.outlier_only = ImageU8(W, H, 1, 0);

  std::vector<Eigen::Matrix<float, 3, 4>> transforms(static_cast<std::size_t>(motion_labels));
  for (int i = 0; i < motion_labels; ++i)
    transforms[std::size_t(i)] = se3Exp(twists[std::size_t(i)]).topRows<3>().cast<float>();
  const label_pixel::DataCostTerms terms = label_pixel::dataCostTerms(frame2.intrinsics, config);
  const float outlier_cost = float(config.outlier_cost);
  const sampling_detail::HostChannel intensity2{frame2.intensity, 0}, depth2{frame2.depth, 0};
  const std::size_t plane = std::size_t(W) * H;

#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const std::size_t idx = std::size_t(y) * W + x;
      const Eigen::Vector3f P(frame1.points(x, y, 0), frame1.points(x, y, 1), frame1.points(x, y, 2));
      if (!std::isfinite(P.z())) {
        problem.outlier_only.data[idx] = 1;
        for (int i = 0; i < n; ++i) problem.data_cost[i * plane + idx] = 0.f;
        continue;
      }
      if (occluded && occluded->data[idx]) continue;  // section 6: no data term, the regulariser decides
      problem.data_cost[std::size_t(motion_labels) * plane + idx] = outlier_cost;
      const float I1 = frame1.intensity(x, y);
      for (int i = 0; i < motion_labels; ++i) {
        const Eigen::Vector3f P2 = transforms[std::size_t(i)] * P.homogeneous();
        problem.data_cost[std::size_t(i) * plane + idx] =
            label_pixel::motionLabelCost(P2.data(), I1, intensity2, depth2, W, H, terms);
      }
    }
  }
}

void addSwitchingCost(const ImageI32& carried, float cost, LabelProblem& problem) {
  if (!carried.sameSize(problem.width, problem.height))
    throw InputError("switching cost: carried labels of " + std::to_string(carried.width) + "x" +
                     std::to_string(carried.height) + " for a " + std::to_string(problem.width) + "x" +
                     std::to_string(problem.height) + " label problem");
  const std::size_t plane = std::size_t(problem.width) * problem.height;
#pragma omp parallel for schedule(static)
  for (std::size_t idx = 0; idx < plane; ++idx) {
    const int own = carried.data[idx];
    if (own < 0 || problem.outlier_only.data[idx]) continue;
    for (int i = 0; i < problem.count; ++i)
      if (i != own) problem.data_cost[std::size_t(i) * plane + idx] += cost;
  }
}

double switchingEnergy(const ImageI32& carried, float cost, const LabelProblem& problem, const SoftLabels& u) {
  const std::size_t plane = u.planeSize();
  double leaving = 0.0;
  for (std::size_t idx = 0; idx < plane; ++idx) {
    const int own = carried.data[idx];
    if (own < 0 || problem.outlier_only.data[idx]) continue;
    leaving += 1.0 - double(u.data[std::size_t(own) * plane + idx]);
  }
  return double(cost) * leaving;
}

namespace {

// Regulariser value of one pixel of one label given its weighted forward differences.
inline double regulariserTerm(Regularizer reg, double qx, double qy) {
  return reg == Regularizer::TotalVariation ? std::sqrt(qx * qx + qy * qy) : qx * qx + qy * qy;
}

}  // namespace

double labelEnergy(const LabelProblem& problem, const SoftLabels& u) {
  const int W = problem.width, H = problem.height, n = problem.count;
  const std::size_t plane = std::size_t(W) * H;
  double energy = 0;
#pragma omp parallel for reduction(+ : energy) schedule(static)
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const std::size_t idx = std::size_t(y) * W + x;
      for (int i = 0; i < n; ++i) {
        const float* ui = u.plane(i);
        energy += double(ui[idx]) * problem.data_cost[i * plane + idx];
        const double qx = x + 1 < W ? problem.weight_x.data[idx] * (ui[idx + 1] - ui[idx]) : 0.0;
        const double qy = y + 1 < H ? problem.weight_y.data[idx] * (ui[idx + W] - ui[idx]) : 0.0;
        energy += problem.lambda * regulariserTerm(problem.regularizer, qx, qy);
      }
    }
  }
  return energy;
}

namespace {

// Row kernels of the primal-dual iteration, written on raw restrict pointers so that the compiler
// vectorises them (inside OpenMP regions it often cannot prove the arrays do not alias).
void dualRowQuadratic(int W, const float* __restrict ub, const float* __restrict ub_down, float* __restrict px,
                      float* __restrict py, const float* __restrict step_x, const float* __restrict step_y,
                      const float* __restrict shrink_x, const float* __restrict shrink_y) {
  for (int x = 0; x < W; ++x) {
    px[x] = label_pixel::dualQuadratic(label_pixel::dualAscent(px[x], step_x[x], ub[x + 1] - ub[x]), shrink_x[x]);
    py[x] = label_pixel::dualQuadratic(label_pixel::dualAscent(py[x], step_y[x], ub_down[x] - ub[x]), shrink_y[x]);
  }
}

void dualRowTv(int W, const float* __restrict ub, const float* __restrict ub_down, float* __restrict px,
               float* __restrict py, const float* __restrict step_x, const float* __restrict step_y, float inv_lambda) {
  for (int x = 0; x < W; ++x) {
    const float qx = label_pixel::dualAscent(px[x], step_x[x], ub[x + 1] - ub[x]);
    const float qy = label_pixel::dualAscent(py[x], step_y[x], ub_down[x] - ub[x]);
    const float scale = label_pixel::dualTvScale(qx, qy, inv_lambda);
    px[x] = qx * scale;
    py[x] = qy * scale;
  }
}

void primalRowCandidate(int W, const float* __restrict u, const float* __restrict data_cost, const float* __restrict px,
                        const float* __restrict py, const float* __restrict py_up, const float* __restrict rx,
                        const float* __restrict ry, const float* __restrict rx_left, const float* __restrict ry_up,
                        const float* __restrict tau, float* __restrict out) {
  // K^T p = -(weighted backward divergence of p); x = 0 has no left neighbour (rx_left = 0).
  out[0] = label_pixel::primalCandidate(
      u[0], tau[0], label_pixel::divergence(rx[0], px[0], ry[0], py[0], 0.f, 0.f, ry_up[0], py_up[0]), data_cost[0]);
  for (int x = 1; x < W; ++x) {
    const float divergence =
        label_pixel::divergence(rx[x], px[x], ry[x], py[x], rx_left[x], px[x - 1], ry_up[x], py_up[x]);
    out[x] = label_pixel::primalCandidate(u[x], tau[x], divergence, data_cost[x]);
  }
}

float primalRowCommit(int W, const float* __restrict candidate, float* __restrict u, float* __restrict u_bar) {
  float max_change = 0.f;
  for (int x = 0; x < W; ++x) {
    const float old = u[x];
    max_change = std::max(max_change, label_pixel::change(candidate[x], old));
    u[x] = candidate[x];
    u_bar[x] = label_pixel::extrapolate(candidate[x], old);
  }
  return max_change;
}

class CpuLabelOptimizer final : public LabelOptimizer {
 public:
  std::string name() const override { return "cpu"; }

  LabelStats optimize(const LabelProblem& problem, SoftLabels& u, LabelDual& dual, int iterations,
                      double tolerance) override {
    const int W = problem.width, H = problem.height, n = problem.count;
    if (u.width != W || u.height != H || u.count != n)
      throw InputError("label step: labels are " + std::to_string(u.width) + "x" + std::to_string(u.height) + "x" +
                       std::to_string(u.count) + " but the problem is " + std::to_string(W) + "x" + std::to_string(H) +
                       "x" + std::to_string(n));
    if (dual.width != W || dual.height != H || dual.count != n) dual.reset(W, H, n);
    const std::size_t plane = std::size_t(W) * H;
    const float* rx = problem.weight_x.ptr();
    const float* ry = problem.weight_y.ptr();
    const bool tv = problem.regularizer == Regularizer::TotalVariation;
    const float lambda = float(problem.lambda);

    // Diagonal preconditioning (label_pixel::stepSizes).
    sigma_x_.resize(plane);
    sigma_y_.resize(plane);
    shrink_x_.resize(plane);
    shrink_y_.resize(plane);
    tau_.resize(plane);
    rx_left_.resize(plane);
    ry_up_.resize(plane);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = std::size_t(y) * W + x;
        rx_left_[i] = x > 0 ? rx[i - 1] : 0.f;
        ry_up_[i] = y > 0 ? ry[i - W] : 0.f;
        const label_pixel::StepSizes s = label_pixel::stepSizes(rx[i], ry[i], rx_left_[i], ry_up_[i], tv, lambda);
        sigma_x_[i] = s.sigma_rx;
        sigma_y_[i] = s.sigma_ry;
        shrink_x_[i] = s.shrink_x;
        shrink_y_[i] = s.shrink_y;
        tau_[i] = s.tau;
      }
    // u_bar carries W + 1 padding floats so the forward differences of the last row/column read valid memory
    // (their weights are 0, so the padding never contributes).
    u_bar_.assign(u.data.size() + std::size_t(W) + 1, 0.f);
    std::copy(u.data.begin(), u.data.end(), u_bar_.begin());
    zero_row_.assign(std::size_t(W) + 1, 0.f);
    const float inv_lambda = 1.f / lambda;

    LabelStats stats;
    for (int it = 0; it < iterations; ++it) {
      // Dual ascent + prox of sigma Q*; branch-free rows so the compiler vectorises them.
#pragma omp parallel for schedule(static)
      for (int y = 0; y < H; ++y) {
        const std::size_t row = std::size_t(y) * W;
        const float* sxr = sigma_x_.data() + row;
        const float* syr = sigma_y_.data() + row;
        const float* kxr = shrink_x_.data() + row;
        const float* kyr = shrink_y_.data() + row;
        for (int label = 0; label < n; ++label) {
          const float* ub = u_bar_.data() + label * plane + row;
          float* px = dual.p.data() + (2 * label) * plane + row;
          float* py = dual.p.data() + (2 * label + 1) * plane + row;
          if (tv)
            dualRowTv(W, ub, ub + W, px, py, sxr, syr, inv_lambda);
          else
            dualRowQuadratic(W, ub, ub + W, px, py, sxr, syr, kxr, kyr);
        }
      }
      // Primal descent, projection onto the simplex per pixel, extrapolation (theta = 1).
      float max_change = 0.f;
#pragma omp parallel reduction(max : max_change)
      {
        std::vector<float> candidate(static_cast<std::size_t>(n) * W);
#pragma omp for schedule(static)
        for (int y = 0; y < H; ++y) {
          const std::size_t row = std::size_t(y) * W;
          const float* rxr = rx + row;
          const float* ryr = ry + row;
          const float* rlr = rx_left_.data() + row;
          const float* rur = ry_up_.data() + row;
          const float* taur = tau_.data() + row;
          for (int label = 0; label < n; ++label) {
            const float* px = dual.p.data() + (2 * label) * plane + row;
            const float* py = dual.p.data() + (2 * label + 1) * plane + row;
            const float* py_up = y > 0 ? py - W : zero_row_.data();
            const float* ur = u.data.data() + label * plane + row;
            const float* dr = problem.data_cost.data() + label * plane + row;
            primalRowCandidate(W, ur, dr, px, py, py_up, rxr, ryr, rlr, rur, taur,
                               candidate.data() + std::size_t(label) * W);
          }
          for (int x = 0; x < W; ++x) {
            if (problem.outlier_only.data[row + x]) {
              for (int label = 0; label < n; ++label)
                candidate[std::size_t(label) * W + x] = label == n - 1 ? 1.f : 0.f;
              continue;
            }
            projectOntoSimplexStrided(candidate.data() + x, n, W);
          }
          for (int label = 0; label < n; ++label)
            max_change = std::max(
                max_change, primalRowCommit(W, candidate.data() + std::size_t(label) * W,
                                            u.data.data() + label * plane + row, u_bar_.data() + label * plane + row));
        }
      }
      stats.iterations = it + 1;
      stats.last_change = max_change;
      if (max_change < tolerance) break;
    }
    stats.energy = labelEnergy(problem, u);
    return stats;
  }

 private:
  std::vector<float> sigma_x_, sigma_y_, shrink_x_, shrink_y_, tau_, rx_left_, ry_up_, u_bar_, zero_row_;
};

}  // namespace

std::unique_ptr<LabelOptimizer> makeCpuLabelOptimizer() { return std::make_unique<CpuLabelOptimizer>(); }

#ifndef MCFLOW_HAVE_CUDA
std::unique_ptr<LabelOptimizer> makeCudaLabelOptimizer() {
  std::string why;
  cudaBackendAvailable(&why);
  throw BackendError("CUDA backend requested but unavailable: " + why);
}
#endif

}  // namespace mc_flow
