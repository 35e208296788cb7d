#include <gtest/gtest.h>

#include <random>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/solve_backend.h"

using namespace mc_flow;

namespace {

LabelProblem makeProblem(int W, int H, int n, Regularizer reg, double lambda, unsigned seed) {
  LabelProblem p;
  p.width = W;
  p.height = H;
  p.count = n;
  p.regularizer = reg;
  p.lambda = lambda;
  p.data_cost.assign(std::size_t(W) * H * n, 0.f);
  p.weight_x = ImageF(W, H, 1, 0.f);
  p.weight_y = ImageF(W, H, 1, 0.f);
  p.outlier_only = ImageU8(W, H, 1, 0);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> cost(0.f, 3.f), weight(0.05f, 1.f);
  for (auto& d : p.data_cost) d = cost(rng);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (x + 1 < W) p.weight_x(x, y) = weight(rng);
      if (y + 1 < H) p.weight_y(x, y) = weight(rng);
    }
  return p;
}

// Independent reference for the quadratic case: projected gradient descent with step 1/L on the same energy
// (smooth + simplex constraint), run to convergence.
SoftLabels projectedGradientReference(const LabelProblem& p, int iterations) {
  const int W = p.width, H = p.height, n = p.count;
  SoftLabels u(W, H, n, 1.f / n);
  double max_w = 0;
  for (float w : p.weight_x.data) max_w = std::max<double>(max_w, w);
  for (float w : p.weight_y.data) max_w = std::max<double>(max_w, w);
  const double L = 2.0 * p.lambda * 8.0 * max_w * max_w;  // ||K||^2 <= 8 max r^2
  const double step = 1.0 / L;
  std::vector<float> grad(u.data.size());
  for (int it = 0; it < iterations; ++it) {
    std::fill(grad.begin(), grad.end(), 0.f);
    for (int i = 0; i < n; ++i) {
      const float* ui = u.plane(i);
      float* gi = grad.data() + std::size_t(i) * u.planeSize();
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const std::size_t k = std::size_t(y) * W + x;
          gi[k] += p.data_cost[std::size_t(i) * u.planeSize() + k];
          if (x + 1 < W) {
            const double r = p.weight_x.data[k], g = 2.0 * p.lambda * r * r * (ui[k + 1] - ui[k]);
            gi[k] -= float(g);
            gi[k + 1] += float(g);
          }
          if (y + 1 < H) {
            const double r = p.weight_y.data[k], g = 2.0 * p.lambda * r * r * (ui[k + W] - ui[k]);
            gi[k] -= float(g);
            gi[k + W] += float(g);
          }
        }
    }
    std::vector<float> v(static_cast<std::size_t>(n));
    for (std::size_t k = 0; k < u.planeSize(); ++k) {
      for (int i = 0; i < n; ++i)
        v[std::size_t(i)] =
            u.data[std::size_t(i) * u.planeSize() + k] - float(step) * grad[std::size_t(i) * u.planeSize() + k];
      projectOntoSimplex(v.data(), n);
      for (int i = 0; i < n; ++i) u.data[std::size_t(i) * u.planeSize() + k] = v[std::size_t(i)];
    }
  }
  return u;
}

}  // namespace

TEST(SimplexProjection, MatchesBruteForceOnRandomVectors) {
  std::mt19937 rng(3);
  std::normal_distribution<float> g(0.f, 1.f);
  for (int trial = 0; trial < 200; ++trial) {
    const int n = 2 + trial % 6;
    std::vector<float> v(static_cast<std::size_t>(n)), p;
    for (auto& x : v) x = g(rng);
    p = v;
    projectOntoSimplex(p.data(), n);
    float sum = 0;
    for (float x : p) {
      EXPECT_GE(x, 0.f);
      sum += x;
    }
    EXPECT_NEAR(sum, 1.f, 1e-5f);
    // Optimality: no random simplex point is closer to v.
    auto dist2 = [&](const std::vector<float>& q) {
      double d = 0;
      for (int i = 0; i < n; ++i)
        d += double(q[std::size_t(i)] - v[std::size_t(i)]) * (q[std::size_t(i)] - v[std::size_t(i)]);
      return d;
    };
    std::uniform_real_distribution<float> uni(0.f, 1.f);
    for (int k = 0; k < 50; ++k) {
      std::vector<float> q(static_cast<std::size_t>(n));
      float s = 0;
      for (auto& x : q) s += (x = -std::log(uni(rng) + 1e-7f));
      for (auto& x : q) x /= s;
      EXPECT_LE(dist2(p), dist2(q) + 1e-6);
    }
  }
}

TEST(SimplexProjection, KeepsPointsAlreadyOnTheSimplex) {
  float v[3] = {0.2f, 0.5f, 0.3f};
  projectOntoSimplex(v, 3);
  EXPECT_NEAR(v[0], 0.2f, 1e-6f);
  EXPECT_NEAR(v[1], 0.5f, 1e-6f);
  EXPECT_NEAR(v[2], 0.3f, 1e-6f);
}

TEST(LabelOptimization, QuadraticPrimalDualMatchesProjectedGradientReference) {
  const LabelProblem p = makeProblem(9, 7, 3, Regularizer::Quadratic, 1.5, 7);
  SoftLabels u(p.width, p.height, p.count, 1.f / 3.f);
  LabelDual dual;
  const LabelStats st = makeCpuLabelOptimizer()->optimize(p, u, dual, 20000, 1e-7);
  const SoftLabels ref = projectedGradientReference(p, 40000);
  float max_diff = 0;
  for (std::size_t i = 0; i < u.data.size(); ++i) max_diff = std::max(max_diff, std::fabs(u.data[i] - ref.data[i]));
  EXPECT_LT(max_diff, 2e-3f) << "primal-dual ran " << st.iterations << " iterations";
  EXPECT_NEAR(st.energy, labelEnergy(p, ref), 1e-3 * std::fabs(st.energy));
}

TEST(LabelOptimization, TvEnergyNotAboveAnyPerturbedSolution) {
  const LabelProblem p = makeProblem(10, 8, 4, Regularizer::TotalVariation, 0.8, 11);
  SoftLabels u(p.width, p.height, p.count, 0.25f);
  LabelDual dual;
  const LabelStats st = makeCpuLabelOptimizer()->optimize(p, u, dual, 5000, 1e-7);
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.f, 0.05f);
  for (int trial = 0; trial < 100; ++trial) {
    SoftLabels q = u;
    std::vector<float> v(static_cast<std::size_t>(p.count));
    for (std::size_t k = 0; k < q.planeSize(); ++k) {
      for (int i = 0; i < p.count; ++i) v[std::size_t(i)] = q.data[std::size_t(i) * q.planeSize() + k] + g(rng);
      projectOntoSimplex(v.data(), p.count);
      for (int i = 0; i < p.count; ++i) q.data[std::size_t(i) * q.planeSize() + k] = v[std::size_t(i)];
    }
    EXPECT_LE(st.energy, labelEnergy(p, q) + 1e-3);
  }
}

TEST(LabelOptimization, TvGivesSharperTransitionsThanQuadratic) {
  // Two labels whose data costs cross linearly from left to right: TV snaps to a sharp boundary,
  // the quadratic regulariser interpolates over a band.
  const int W = 40, H = 6;
  auto ramp = [&](Regularizer reg, double lambda) {
    LabelProblem p;
    p.width = W;
    p.height = H;
    p.count = 2;
    p.regularizer = reg;
    p.lambda = lambda;
    p.data_cost.assign(std::size_t(W) * H * 2, 0.f);
    p.weight_x = ImageF(W, H, 1, 1.f);
    p.weight_y = ImageF(W, H, 1, 1.f);
    for (int y = 0; y < H; ++y) {
      p.weight_x(W - 1, y) = 0.f;
      for (int x = 0; x < W; ++x) {
        const float s = (x - (W - 1) / 2.f) / 10.f;
        p.data_cost[std::size_t(y) * W + x] = std::max(0.f, s) * 0.2f;
        p.data_cost[std::size_t(W) * H + std::size_t(y) * W + x] = std::max(0.f, -s) * 0.2f;
      }
    }
    for (int x = 0; x < W; ++x) p.weight_y(x, H - 1) = 0.f;
    p.outlier_only = ImageU8(W, H, 1, 0);
    SoftLabels u(W, H, 2, 0.5f);
    LabelDual dual;
    makeCpuLabelOptimizer()->optimize(p, u, dual, 4000, 1e-7);
    int intermediate = 0;
    for (int x = 0; x < W; ++x) intermediate += (u.at(0, x, H / 2) > 0.05f && u.at(0, x, H / 2) < 0.95f);
    return intermediate;
  };
  const int tv = ramp(Regularizer::TotalVariation, 0.5);
  const int quad = ramp(Regularizer::Quadratic, 2.0);
  EXPECT_LE(tv, 2);
  EXPECT_GE(quad, 6);
}

TEST(LabelOptimization, OutlierOnlyPixelsStayOnTheOutlierLabel) {
  LabelProblem p = makeProblem(8, 8, 3, Regularizer::Quadratic, 1.0, 2);
  p.outlier_only(3, 4) = 1;
  SoftLabels u(8, 8, 3, 1.f / 3.f);
  LabelDual dual;
  makeCpuLabelOptimizer()->optimize(p, u, dual, 200, 0);
  EXPECT_FLOAT_EQ(u.at(2, 3, 4), 1.f);
  EXPECT_FLOAT_EQ(u.at(0, 3, 4), 0.f);
  for (std::size_t k = 0; k < u.planeSize(); ++k) {
    float s = 0;
    for (int i = 0; i < 3; ++i) s += u.data[i * u.planeSize() + k];
    EXPECT_NEAR(s, 1.f, 1e-5f);
  }
}

TEST(LabelOptimization, DataTermAloneGivesArgminLabel) {
  LabelProblem p = makeProblem(6, 5, 4, Regularizer::Quadratic, 1e-6, 9);
  // A clear winner per pixel (gap >= 0.5), so the expected answer is unambiguous.
  for (std::size_t k = 0; k < 30; ++k) {
    const std::size_t winner = k % 4;
    for (std::size_t i = 0; i < 4; ++i) p.data_cost[i * 30 + k] = i == winner ? 0.f : 0.5f + p.data_cost[i * 30 + k];
  }
  SoftLabels u(6, 5, 4, 0.25f);
  LabelDual dual;
  makeCpuLabelOptimizer()->optimize(p, u, dual, 500, 0);
  for (std::size_t k = 0; k < u.planeSize(); ++k) {
    int best = 0;
    for (int i = 1; i < 4; ++i)
      if (p.data_cost[i * u.planeSize() + k] < p.data_cost[best * u.planeSize() + k]) best = i;
    EXPECT_GT(u.data[best * u.planeSize() + k], 0.99f);
  }
}

TEST(LabelOptimization, SwitchingCostRaisesEveryLabelButTheCarriedOne) {
  LabelProblem p = makeProblem(4, 2, 3, Regularizer::Quadratic, 1.0, 5);
  p.outlier_only(3, 1) = 1;
  const std::vector<float> before = p.data_cost;
  ImageI32 carried(4, 2, 1, -1);
  carried(0, 0) = 0;
  carried(1, 0) = 1;
  carried(2, 0) = 2;  // the outlier label: a pixel carried as an outlier keeps it cheaply too
  carried(3, 1) = 0;  // no depth: only the outlier label is feasible there, nothing to add
  addSwitchingCost(carried, 0.25f, p);
  const std::size_t plane = 8;
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x)
      for (int i = 0; i < 3; ++i) {
        const std::size_t k = std::size_t(y) * 4 + std::size_t(x), at = std::size_t(i) * plane + k;
        const int own = carried(x, y);
        const bool raised = own >= 0 && i != own && !p.outlier_only.data[k];
        EXPECT_EQ(p.data_cost[at], raised ? before[at] + 0.25f : before[at])
            << "pixel " << x << "," << y << " label " << i;
      }
  EXPECT_THROW(addSwitchingCost(ImageI32(3, 2, 1, -1), 0.25f, p), InputError);
}

TEST(LabelOptimization, BackendSelection) {
  std::string note;
  EXPECT_EQ(resolveBackend(Backend::Cpu, &note), Backend::Cpu);
  EXPECT_NE(note.find("cpu"), std::string::npos);
  std::string why;
  if (!cudaBackendAvailable(&why)) {
    EXPECT_FALSE(why.empty());
    EXPECT_THROW(resolveBackend(Backend::Cuda), BackendError);
    EXPECT_THROW(makeCudaLabelOptimizer(), BackendError);
    EXPECT_EQ(resolveBackend(Backend::Auto, &note), Backend::Cpu);
    EXPECT_NE(note.find(why), std::string::npos) << note;
  }
}
