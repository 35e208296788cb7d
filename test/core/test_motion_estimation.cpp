#include <gtest/gtest.h>

#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/pyramid.h"
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
  EXPECT_EQ(estimateMotionsAtLevel(s.p1[0], s.p2[0], s.u, nullptr, wrong, config).stop, MotionStop::NoLabels);
}
