#include <gtest/gtest.h>

#include "mc_flow/core/label_adaptation.h"

using namespace mc_flow;

namespace {

// Three vertical bands of points at 2 m, one label each (+ outlier plane).
void makeBands(SoftLabels& u, ImageF& points, int W = 30, int H = 10) {
  u = SoftLabels(W, H, 4, 0.f);
  points = ImageF(W, H, 3, 0.f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      u.at(x * 3 / W, x, y) = 1.f;
      points(x, y, 0) = (x - W / 2) * 0.01f;
      points(x, y, 1) = (y - H / 2) * 0.01f;
      points(x, y, 2) = 2.f;
    }
}

}  // namespace

TEST(LabelAdaptation, MergesLabelsWithSimilarMotion) {
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  Vector6d a = Vector6d::Zero(), b = Vector6d::Zero(), c = Vector6d::Zero();
  a(0) = 0.020;
  b(0) = 0.021;  // 1 mm apart: same motion
  c(0) = -0.03;  // clearly different
  std::vector<Vector6d> twists{a, b, c};
  Config config;
  const AdaptationStats st = adaptLabelCount(u, twists, points, 300, config);
  EXPECT_EQ(st.merged, 1);
  EXPECT_EQ(st.removed, 0);
  ASSERT_EQ(u.count, 3);
  ASSERT_EQ(twists.size(), 2u);
  EXPECT_NEAR(twists[0](0), 0.0205, 1e-6);  // support-weighted average (equal supports)
  EXPECT_NEAR(u.support(0), 200.0, 1e-3);
  EXPECT_NEAR(twists[1](0), -0.03, 1e-9);
}

TEST(LabelAdaptation, RotationDifferenceBlocksMerging) {
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  Vector6d a = Vector6d::Zero(), b = Vector6d::Zero(), c = Vector6d::Zero();
  b(5) = 0.05;  // 3 deg about the optical axis: points near the axis barely move, the rotation differs
  c(0) = 0.5;
  std::vector<Vector6d> twists{a, b, c};
  Config config;
  const AdaptationStats st = adaptLabelCount(u, twists, points, 300, config);
  EXPECT_EQ(st.merged, 0);
  EXPECT_EQ(u.count, 4);
}

TEST(LabelAdaptation, TinyLabelsGoToTheOutlierLabel) {
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  // Label 1 keeps only 2 pixels; the rest of its band goes to label 0.
  for (int y = 0; y < u.height; ++y)
    for (int x = 0; x < u.width; ++x)
      if (u.at(1, x, y) > 0 && !(y == 0 && x < 12)) {
        u.at(1, x, y) = 0.f;
        u.at(0, x, y) = 1.f;
      }
  ASSERT_NEAR(u.support(1), 2.0, 1e-6);
  Vector6d a = Vector6d::Zero(), b = Vector6d::Zero(), c = Vector6d::Zero();
  a(0) = 0.1;
  b(1) = 0.1;
  c(2) = 0.1;
  std::vector<Vector6d> twists{a, b, c};
  Config config;
  config.min_support_fraction = 0.05;  // 15 of 300 pixels
  const AdaptationStats st = adaptLabelCount(u, twists, points, 300, config);
  EXPECT_EQ(st.removed, 1);
  ASSERT_EQ(u.count, 3);
  EXPECT_NEAR(u.support(u.outlier()), 2.0, 1e-6);
  EXPECT_NEAR(twists[1](2), 0.1, 1e-12);
}

TEST(LabelAdaptation, CentroidsAreSupportWeighted) {
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  const auto c = labelCentroids(u, points);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_LT(c[0].x(), c[1].x());
  EXPECT_LT(c[1].x(), c[2].x());
  EXPECT_NEAR(c[1].z(), 2.0, 1e-6);
}
