#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cstdlib>
#include <cstdio>
#include <string>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/motion_estimation_pixel.h"
#include "mc_flow/core/motion_step_control.h"
#include "mc_flow/core/pyramid.h"
#include "coupled_labels.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "test_helpers.h"

using namespace mc_flow;

namespace {

// Coarse-to-fine IRLS with one label covering everything (plain robust dense VO).
std::vector<Vector6d> estimateSingle(const test::TwoPlaneScene& s, const Config& config, int label_count = 1) {
  const int levels = pyramidLevelCount(s.frame1.width(), s.frame1.height(), config.coarsest_min_width);
  const Pyramid p1 = buildPyramid(s.frame1, s.K, levels, config);
  const Pyramid p2 = buildPyramid(s.frame2, s.K, levels, config);
  std::vector<Vector6d> twists(std::size_t(label_count), Vector6d::Zero());
  for (int level = levels - 1; level >= 0; --level) {
    SoftLabels u(p1[level].points.width, p1[level].points.height, label_count + 1, 0.f);
    for (int y = 0; y < u.height; ++y)
      for (int x = 0; x < u.width; ++x) {
        // Split the image into vertical bands, one per label: all labels see the same motion.
        const int label = std::min(label_count - 1, x * label_count / u.width);
        u.at(label, x, y) = 1.f;
      }
    estimateMotionsAtLevel(p1[level], p2[level], u, nullptr, twists, config);
  }
  return twists;
}

}  // namespace

TEST(MotionEstimation, DepthCauchyScaleGrowsWithTheSquareOfDepthBeyondTheReference) {
  EXPECT_EQ(motion_pixel::depthCauchyScale(0.03f, 0.f, 4.f), 0.03f);   // the model off
  EXPECT_EQ(motion_pixel::depthCauchyScale(0.03f, 1.5f, 1.f), 0.03f);  // nearer than the reference
  EXPECT_EQ(motion_pixel::depthCauchyScale(0.03f, 1.5f, 1.5f), 0.03f);
  EXPECT_FLOAT_EQ(motion_pixel::depthCauchyScale(0.03f, 1.5f, 3.f), 0.12f);  // twice as far: four times the scale
  EXPECT_FLOAT_EQ(motion_pixel::depthCauchyScale(0.02f, 2.f, 5.f), 0.125f);
}

TEST(MotionEstimation, RecoversSingleRigidMotionToMillimetreAndTwentiethOfDegree) {
  Vector6d truth;
  truth << 0.03, -0.015, 0.02, 0.02, -0.03, 0.015;  // 3 cm / ~2 deg: a large inter-frame motion
  const Eigen::Matrix4d T = se3Exp(truth);
  const test::TwoPlaneScene s = test::renderTwoPlaneScene(320, 240, T);
  Config config;
  config.motion_iterations_per_level = 10;
  const std::vector<Vector6d> est = estimateSingle(s, config);
  const Eigen::Matrix4d E = se3Exp(est[0]);
  const Eigen::Matrix4d D = E.inverse() * T;
  const double translation_error = D.topRightCorner<3, 1>().norm();
  const double rotation_error_deg = Eigen::AngleAxisd(Eigen::Matrix3d(D.topLeftCorner<3, 3>())).angle() * 180.0 / M_PI;
  EXPECT_LT(translation_error, 0.001) << "estimated twist " << est[0].transpose();
  EXPECT_LT(rotation_error_deg, 0.05) << "estimated twist " << est[0].transpose();
}

TEST(MotionEstimation, JointLabelsWithTheSameMotionAgree) {
  Vector6d truth;
  truth << -0.02, 0.01, -0.015, -0.01, 0.02, 0.01;
  const test::TwoPlaneScene s = test::renderTwoPlaneScene(320, 240, se3Exp(truth));
  Config config;
  config.motion_iterations_per_level = 10;
  const std::vector<Vector6d> est = estimateSingle(s, config, 3);
  for (const Vector6d& xi : est) {
    const Eigen::Matrix4d D = se3Exp(xi).inverse() * se3Exp(truth);
    EXPECT_LT((D.topRightCorner<3, 1>().norm()), 0.004) << xi.transpose();
  }
}

TEST(MotionEstimation, ZeroMotionStaysZero) {
  const test::TwoPlaneScene s = test::renderTwoPlaneScene(160, 120, Eigen::Matrix4d::Identity());
  Config config;
  const std::vector<Vector6d> est = estimateSingle(s, config);
  EXPECT_LT(est[0].norm(), 1e-4) << est[0].transpose();
}

// One pyramid level of the two-plane scene moved by `truth`, every pixel on motion label 0.
struct OneLevelScene {
  Vector6d truth;
  Pyramid p1, p2;
  SoftLabels u{160, 120, 2, 0.f};
  OneLevelScene() {
    truth << 0.01, 0.0, 0.005, 0.0, 0.01, 0.0;
    const test::TwoPlaneScene s = test::renderTwoPlaneScene(160, 120, se3Exp(truth));
    p1 = buildPyramid(s.frame1, s.K, 1, Config());
    p2 = buildPyramid(s.frame2, s.K, 1, Config());
    std::fill(u.plane(0), u.plane(0) + u.planeSize(), 1.f);
  }
};

TEST(MotionEstimation, RobustCostDecreasesAtALevel) {
  const OneLevelScene s;
  Config config;
  std::vector<Vector6d> twists(1, Vector6d::Zero());
  const MotionLevelStats st = estimateMotionsAtLevel(s.p1[0], s.p2[0], s.u, nullptr, twists, config);
  EXPECT_GT(st.iterations, 1);
  EXPECT_LT(st.cost_after, 0.5 * st.cost_before);
  EXPECT_TRUE(st.stop == MotionStop::SmallUpdate || st.stop == MotionStop::IterationLimit) << toString(st.stop);
}

// Each way the IRLS loop can stop is reported, as dvo_slam does per level.
TEST(MotionEstimation, ReportsWhyTheLevelStopped) {
  const OneLevelScene s;
  Config config;
  std::vector<Vector6d> twists(1, Vector6d::Zero());
  config.motion_iterations_per_level = 2;
  config.motion_min_update = 0;
  MotionLevelStats st = estimateMotionsAtLevel(s.p1[0], s.p2[0], s.u, nullptr, twists, config);
  EXPECT_EQ(st.stop, MotionStop::IterationLimit);
  EXPECT_EQ(st.iterations, 2);

  twists.assign(1, s.truth);
  config.motion_iterations_per_level = 50;
  config.motion_min_update = 1e-3;  // already at the truth: the first step is tiny
  st = estimateMotionsAtLevel(s.p1[0], s.p2[0], s.u, nullptr, twists, config);
  EXPECT_EQ(st.stop, MotionStop::SmallUpdate);
  EXPECT_LT(st.iterations, 50);

  SoftLabels outliers(160, 120, 2, 0.f);  // every pixel on the outlier label: nothing carries residuals
  std::fill(outliers.plane(1), outliers.plane(1) + outliers.planeSize(), 1.f);
  st = estimateMotionsAtLevel(s.p1[0], s.p2[0], outliers, nullptr, twists, config);
  EXPECT_EQ(st.stop, MotionStop::TooFewPixels);

  std::vector<Vector6d> wrong(2, Vector6d::Zero());
  try {
    estimateMotionsAtLevel(s.p1[0], s.p2[0], s.u, nullptr, wrong, config);
    ADD_FAILURE() << "2 twists for " << s.u.count << " label planes accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("2 twists for " + std::to_string(s.u.count)), std::string::npos) << e.what();
  }
  SoftLabels only_outlier(160, 120, 1, 1.f);
  std::vector<Vector6d> none;
  EXPECT_EQ(estimateMotionsAtLevel(s.p1[0], s.p2[0], only_outlier, nullptr, none, config).stop, MotionStop::NoLabels);
}

// ---- the CPU accumulator's normal equations against finite differences ----

namespace {

// A level on which the accumulator's linearisation is exact: frame 2's intensity and depth are affine in the
// pixel coordinates, so bilinear sampling reproduces them and the pyramid's gradients are their exact slopes.
// Frame 1 sees the same affine surface (zero residuals at zero twists) with valid depth only in the centre, so
// small motions never move a pixel out of view or next to the border. Two motion labels blend smoothly across
// the image (every pixel has both, and some outlier mass), so the label coupling of eq. 2 is exercised.
struct AffineLevel {
  static constexpr int kW = 40, kH = 30, kMargin = 8;
  PyramidLevel frame1, frame2;
  SoftLabels labels{kW, kH, 3, 0.f};

  static float intensityAt(double u, double v) { return float(0.2 + 0.01 * u + 0.008 * v); }
  static float depthAt(double u, double v) { return float(2.0 + 0.01 * u - 0.005 * v); }

  AffineLevel() {
    const Intrinsics K{40.0, 40.0, 19.5, 14.5};
    for (PyramidLevel* level : {&frame1, &frame2}) {
      level->intrinsics = K;
      level->intensity = ImageF(kW, kH, 1, 0.f);
      level->depth = ImageF(kW, kH, 1, 0.f);
      level->intensity_grad = ImageF(kW, kH, 2, 0.f);
      level->depth_grad = ImageF(kW, kH, 2, 0.f);
      for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
          level->intensity(x, y) = intensityAt(x, y);
          level->depth(x, y) = depthAt(x, y);
          level->intensity_grad(x, y, 0) = 0.01f, level->intensity_grad(x, y, 1) = 0.008f;
          level->depth_grad(x, y, 0) = 0.01f, level->depth_grad(x, y, 1) = -0.005f;
        }
    }
    ImageF central_depth(kW, kH, 1, 0.f);
    for (int y = kMargin; y < kH - kMargin; ++y)
      for (int x = kMargin; x < kW - kMargin; ++x) central_depth(x, y) = frame1.depth(x, y);
    frame1.points = backProject(central_depth, K);
    frame2.points = backProject(frame2.depth, K);
    for (int y = 0; y < kH; ++y)
      for (int x = 0; x < kW; ++x) {
        const float s = float(x) / (kW - 1);
        labels.at(0, x, y) = 0.9f - 0.7f * s;
        labels.at(1, x, y) = 0.05f + 0.7f * s;
        labels.at(2, x, y) = 0.05f;
      }
  }

  MotionNormalEquations accumulate(const std::vector<Vector6d>& twists, const Config& config) const {
    auto accumulator = makeCpuMotionAccumulator();
    accumulator->setLevel(frame1, frame2, labels, nullptr, config);
    MotionNormalEquations eq;
    accumulator->accumulate(twists, eq);
    return eq;
  }
};

std::vector<Vector6d> perturbed(std::vector<Vector6d> twists, int index, double h) {
  twists[std::size_t(index / 6)][index % 6] += h;
  return twists;
}

}  // namespace

// The gradient of the robust cost sum m ln(1 + (r/c)^2) (alpha for depth) with respect to the twists is twice the
// accumulated g = sum m w(r) J^T r: the residuals, their Jacobians (chain rule through the projection, the
// sampled gradients and the left Jacobian of SE(3)) and the interpolation weights all enter g.
TEST(MotionNormalEquations, GradientMatchesFiniteDifferencesOfTheCost) {
  const AffineLevel level;
  const Config config;
  Vector6d a, b;
  // Rotations of about 0.05 rad: the left Jacobian of SE(3) then differs from the identity by about 2.5%, ten times
  // the tolerance, so a Jacobian without it fails here. Pixels move by up to 3 px, inside the margin.
  a << 0.03, -0.02, 0.04, 0.04, -0.03, 0.02;
  b << -0.03, 0.02, -0.03, -0.02, 0.04, -0.03;
  const std::vector<Vector6d> twists{a, b};
  const MotionNormalEquations eq = level.accumulate(twists, config);
  ASSERT_GT(eq.pixels, 150);
  // h = 1e-3: smaller steps drown in the float rounding of the cost (1e-5 gives 2e-2), and the central difference's
  // own error is O(h^2). Measured: 8.9e-4 of max |2g| (2 threads, at 4b361dc); tolerance 2e-3. Without the left
  // Jacobian the difference is 3.4e-2.
  const double h = 1e-3;
  double worst = 0;
  for (int k = 0; k < 12; ++k) {
    const double numeric = (level.accumulate(perturbed(twists, k, h), config).cost -
                            level.accumulate(perturbed(twists, k, -h), config).cost) /
                           (2 * h);
    worst = std::max(worst, std::abs(numeric - 2 * eq.g(k)) / eq.g.cwiseAbs().maxCoeff());
    EXPECT_NEAR(numeric, 2 * eq.g(k), 2e-3 * 2 * eq.g.cwiseAbs().maxCoeff()) << "twist component " << k;
  }
  std::printf("[ measured ] gradient: largest FD difference %.2e of max |2g| = %.3g\n", worst,
              2 * eq.g.cwiseAbs().maxCoeff());
}

// At zero residuals the Gauss-Newton Hessian H = sum m w J^T J is the derivative of g (the terms with r vanish),
// so its columns are finite differences of g; this checks H's blocks between the two labels as well.
TEST(MotionNormalEquations, GaussNewtonHessianMatchesFiniteDifferencesOfTheGradient) {
  const AffineLevel level;
  const Config config;
  const std::vector<Vector6d> zero(2, Vector6d::Zero());
  const MotionNormalEquations eq = level.accumulate(zero, config);
  ASSERT_GT(eq.pixels, 150);
  EXPECT_LT(eq.g.cwiseAbs().maxCoeff(), 1e-6 * eq.H.cwiseAbs().maxCoeff()) << "residuals are not zero here";
  // Measured: 1.8e-4 of max |H| (h = 1e-4, 2 threads, at 4b361dc); tolerance 5e-4.
  const double h = 1e-4, scale = eq.H.cwiseAbs().maxCoeff();
  double worst = 0;
  for (int k = 0; k < 12; ++k) {
    const Eigen::VectorXd column =
        (level.accumulate(perturbed(zero, k, h), config).g - level.accumulate(perturbed(zero, k, -h), config).g) /
        (2 * h);
    for (int j = 0; j < 12; ++j) {
      worst = std::max(worst, std::abs(column(j) - eq.H(j, k)) / scale);
      EXPECT_NEAR(column(j), eq.H(j, k), 5e-4 * scale) << "H(" << j << ", " << k << ")";
    }
  }
  const double coupling = eq.H.block<6, 6>(0, 6).cwiseAbs().maxCoeff();
  EXPECT_GT(coupling, 0.05 * scale) << "the labels should be coupled";
  std::printf("[ measured ] Hessian: largest FD difference %.2e of max |H| = %.3g\n", worst, scale);
}

// The damped normal equations are solved per group of coupled labels: the solution must be the whole matrix's
// (an LDLT of everything), whatever the grouping, and the largest group is reported.
TEST(MotionNormalEquations, SolvingCoupledGroupsApartGivesTheWholeSolution) {
  const int n = 7;
  std::srand(7);
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(6 * n, 6 * n);
  auto couple = [&H](int a, int b) {  // a random SPD contribution on the rows and columns of labels a and b
    Eigen::MatrixXd J = Eigen::MatrixXd::Random(12, 12);
    const Eigen::MatrixXd block = J * J.transpose();
    const int idx[2] = {a, b};
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 2; ++c) H.block<6, 6>(6 * idx[r], 6 * idx[c]) += block.block<6, 6>(6 * r, 6 * c);
  };
  // Groups {0, 3, 5} (a chain), {1}, {2, 6}, {4}.
  couple(0, 3);
  couple(3, 5);
  couple(2, 6);
  for (int i = 0; i < n; ++i) H.block<6, 6>(6 * i, 6 * i) += Eigen::MatrixXd::Identity(6, 6);
  const Eigen::VectorXd g = Eigen::VectorXd::Random(6 * n);
  Eigen::VectorXd delta;
  EXPECT_EQ(solveCoupledBlocks(H, g, delta, 0.0), 3);
  const Eigen::VectorXd whole = H.ldlt().solve(-g);
  ASSERT_EQ(delta.size(), whole.size());
  EXPECT_LT((delta - whole).cwiseAbs().maxCoeff(), 1e-9 * whole.cwiseAbs().maxCoeff());
  EXPECT_LT((H * delta + g).norm(), 1e-9 * g.norm());

  // One coupling between the groups joins them.
  couple(5, 2);
  EXPECT_EQ(solveCoupledBlocks(H, g, delta, 0.0), 5);
  EXPECT_LT((H * delta + g).norm(), 1e-9 * g.norm());
  // Sizes that do not fit are refused.
  EXPECT_THROW(solveCoupledBlocks(H, Eigen::VectorXd::Zero(6 * n - 1), delta, 0.0), InputError);
}

// The coupling strength sees a direction that a label's own pixels hardly constrain: with the same off-diagonal block,
// a label whose block is weak along one direction is coupled far more strongly (canonical correlations, not ratios of
// diagonal entries); an off-diagonal block that is the diagonal blocks' geometric mean (the pixels fully shared)
// gives 1 per direction.
TEST(MotionNormalEquations, CouplingStrengthIsTheCanonicalCorrelationOfTheSteps) {
  using Block = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;
  auto strength = [](const Block& A, const Block& C, const Block& B) {
    double La[21], Lb[21];
    choleskyLower6(A.data(), La);
    choleskyLower6(B.data(), Lb);
    return motionCouplingStrength(La, C.data(), Lb);
  };
  const Block I = Block::Identity();
  EXPECT_NEAR(strength(I, 0.05 * I, I), 0.05 * std::sqrt(6.0), 1e-12);
  EXPECT_NEAR(strength(4 * I, 4 * I, 4 * I), std::sqrt(6.0), 1e-12);
  EXPECT_EQ(strength(I, Block::Zero(), I), 0.0);
  // Mixed directions: a block weak along (1, 1, 0, 0, 0, 0)/sqrt(2) only, so no diagonal entry is small.
  Eigen::Matrix<double, 6, 1> v = Eigen::Matrix<double, 6, 1>::Zero();
  v(0) = v(1) = std::sqrt(0.5);
  const Block weak_direction = I - 0.999 * v * v.transpose();
  Block C = Block::Zero();
  C.topLeftCorner<2, 2>() = 0.02 * v.head<2>() * v.head<2>().transpose();
  const double diagonal_ratio = C(0, 0) / std::sqrt(weak_direction(0, 0) * I(0, 0));
  EXPECT_LT(diagonal_ratio, 0.02);
  EXPECT_GT(strength(weak_direction, C, I), 0.5) << "the weak direction's coupling must show";
}

// Groups split at weak couplings in a level's IRLS loop (the scene of the device test in test_cuda,
// DeviceLoopSplitsGroupsAtWeakCouplingsAsTheHostLoopDoes): labels 0-1 and 1-2 blend half and half on wide strips, 0
// and 2 on a few pixels (inside the group), 2 and 3 on a few pixels only. Every coupling kept: one group of four;
// the default threshold: {0, 1, 2} and {3}.
TEST(MotionNormalEquations, TheLevelLoopSplitsGroupsAtWeakCouplings) {
  const SyntheticPair pair = renderSyntheticPair(320, 240);
  Config config;
  const Pyramid p1 = buildPyramid(pair.frame1, pair.intrinsics, 1, config);
  const Pyramid p2 = buildPyramid(pair.frame2, pair.intrinsics, 1, config);
  const SoftLabels u = test::labelsWithWeakAndStrongCouplings(320, 240);
  config.motion_iterations_per_level = 2;
  for (const double min_coupling : {0.0, Config().motion_min_coupling}) {
    config.motion_min_coupling = min_coupling;
    std::vector<Vector6d> twists(4, Vector6d::Zero());
    for (int i = 0; i < 4; ++i) twists[std::size_t(i)] << 0.004 * i, -0.006, 0.01, 0.002, -0.002 * i, 0.001;
    auto accumulator = makeCpuMotionAccumulator();
    const MotionLevelStats stats = estimateMotionsAtLevel(p1[0], p2[0], u, nullptr, twists, config, accumulator.get());
    EXPECT_EQ(stats.largest_block, min_coupling == 0.0 ? 4 : 3) << "min_coupling " << min_coupling;
  }
}

// With a coupling threshold (Config::motion_min_coupling), a weak coupling no longer joins two groups: the labels it
// joined are solved apart, as if their off-diagonal block were zero, while strong couplings stay in the joint solve;
// a weak coupling between two labels that strong ones put in one group stays in that group's matrix.
TEST(MotionNormalEquations, WeakCouplingsAreDroppedFromTheStep) {
  const int n = 4;
  std::srand(11);
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(6 * n, 6 * n);
  // Pixels that blend labels a and b with weights (wa, wb) add wa^2 A, wa wb A and wb^2 A to the blocks (A PSD);
  // pixels of one label add A to its own block.
  auto pixels = [&H](int a, int b, double wa, double wb) {
    const Eigen::MatrixXd J = Eigen::MatrixXd::Random(6, 12);
    const Eigen::MatrixXd A = J * J.transpose() + 0.1 * Eigen::MatrixXd::Identity(6, 6);
    H.block<6, 6>(6 * a, 6 * a) += wa * wa * A;
    H.block<6, 6>(6 * b, 6 * b) += wb * wb * A;
    H.block<6, 6>(6 * a, 6 * b) += wa * wb * A;
    H.block<6, 6>(6 * b, 6 * a) += wa * wb * A;
  };
  for (int i = 0; i < n; ++i) pixels(i, i, 1.0, 0.0);  // each label's own pixels
  for (int i = 0; i < n; ++i) pixels(i, i, 0.0, 1.0);
  pixels(0, 1, 0.5, 0.5);    // strong: as many blended pixels as own ones
  pixels(1, 2, 0.02, 0.02);  // weak
  pixels(2, 3, 0.5, 0.5);    // strong
  const Eigen::VectorXd g = Eigen::VectorXd::Random(6 * n);
  auto strength = [&H](int a, int b) {  // motionCouplingStrength on the blocks, as solveCoupledBlocks computes it
    using Block = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;
    double La[21], Lb[21];
    const Block A = H.block<6, 6>(6 * a, 6 * a), B = H.block<6, 6>(6 * b, 6 * b), C = H.block<6, 6>(6 * a, 6 * b);
    choleskyLower6(A.data(), La);
    choleskyLower6(B.data(), Lb);
    return motionCouplingStrength(La, C.data(), Lb);
  };
  ASSERT_GT(strength(0, 1), 0.1);
  ASSERT_GT(strength(2, 3), 0.1);
  ASSERT_LT(strength(1, 2), 0.01);
  Eigen::VectorXd delta;
  EXPECT_EQ(solveCoupledBlocks(H, g, delta, 0.0), 4);  // every coupling: one group
  EXPECT_LT((H * delta + g).norm(), 1e-9 * g.norm());
  EXPECT_EQ(solveCoupledBlocks(H, g, delta, 0.1), 2);  // the weak one dropped: {0, 1} and {2, 3}
  Eigen::MatrixXd kept = H;
  kept.block<6, 6>(6, 12).setZero();
  kept.block<6, 6>(12, 6).setZero();
  EXPECT_LT((kept * delta + g).norm(), 1e-9 * g.norm());
  EXPECT_GT((H * delta + g).norm(), 1e-6 * g.norm()) << "the dropped coupling should change the step";
  EXPECT_EQ(solveCoupledBlocks(H, g, delta, 1.5), 1);  // above 1: every label apart
  for (int i = 0; i < n; ++i) {
    const Vector6d own = H.block<6, 6>(6 * i, 6 * i).ldlt().solve(-g.segment<6>(6 * i));
    // The shared 6x6 Cholesky (the device's single-label solve) gives the same step.
    using Block = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;
    const Block A = H.block<6, 6>(6 * i, 6 * i);
    double L[21], x[6], b[6];
    choleskyLower6(A.data(), L);
    for (int k = 0; k < 6; ++k) b[k] = -g(6 * i + k);
    choleskySolve6(L, b, x);
    EXPECT_LT((Eigen::Map<const Vector6d>(x) - own).cwiseAbs().maxCoeff(), 1e-9 * own.cwiseAbs().maxCoeff());
    EXPECT_LT((delta.segment<6>(6 * i) - own).cwiseAbs().maxCoeff(), 1e-9 * own.cwiseAbs().maxCoeff()) << "label " << i;
  }

  // A weak coupling inside a group: 3 - 0 strong as well puts {0, 1, 2, 3} in one group (0-1, 2-3 and 3-0 strong),
  // so 1-2 stays in its matrix and the step is the whole matrix's.
  pixels(3, 0, 0.5, 0.5);
  ASSERT_GT(strength(3, 0), 0.1);
  ASSERT_LT(strength(1, 2), 0.01);
  EXPECT_EQ(solveCoupledBlocks(H, g, delta, 0.1), 4);
  EXPECT_LT((H * delta + g).norm(), 1e-9 * g.norm());
}
