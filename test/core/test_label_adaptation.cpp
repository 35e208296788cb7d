#include <gtest/gtest.h>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_adaptation.h"

using namespace mc_flow;

namespace {

// Three vertical bands of points at 2 m, one label each (+ outlier plane): 100 pixels each.
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

LabelCostModel uniformModel(int labels, const Matrix6d& H) {
  LabelCostModel model;
  model.curvature.assign(std::size_t(labels), H);
  model.gradient.assign(std::size_t(labels), Vector6d::Zero());
  return model;
}

}  // namespace

TEST(LabelAdaptation, MergeIncreaseIsTheParallelSumOfTheCurvatures) {
  Matrix6d H = Matrix6d::Identity();
  H(0, 1) = H(1, 0) = 0.3;
  Vector6d a = Vector6d::Zero(), b = Vector6d::Zero();
  a(0) = 0.02;
  b(1) = -0.01;
  const Vector6d d = a - b;
  // For H_a = 2H and H_b = 6H the union's best motion costs (2 * 6 / 8) d^T H d more than two motions.
  EXPECT_NEAR(mergeCostIncrease(2 * H, 6 * H, a, b), 1.5 * d.dot(H * d), 1e-9);
  EXPECT_NEAR(mergeCostIncrease(2 * H, 6 * H, a, b), mergeCostIncrease(6 * H, 2 * H, b, a), 1e-12);
  EXPECT_NEAR(mergeCostIncrease(H, H, a, a), 0.0, 1e-15);
}

TEST(LabelAdaptation, MergesWhenSharingAMotionCostsLessThanALabel) {
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  Vector6d a = Vector6d::Zero(), b = Vector6d::Zero(), c = Vector6d::Zero();
  a(0) = 0.020;
  b(0) = 0.021;  // 1 mm apart: increase 1e5 / 2 * 1e-6 = 0.05
  c(0) = -0.03;  // 5 cm from a: increase 1e5 / 2 * 2.5e-3 = 125
  std::vector<Vector6d> twists{a, b, c};
  LabelCostModel model = uniformModel(3, 1e5 * Matrix6d::Identity());
  Config config;
  config.label_cost = 0.02;  // x 300 valid pixels = 6
  const AdaptationStats st = adaptLabelCount(u, twists, model, 300, config);
  EXPECT_EQ(st.merged, 1);
  EXPECT_EQ(st.removed, 0);
  ASSERT_EQ(u.count, 3);
  ASSERT_EQ(twists.size(), 2u);
  EXPECT_NEAR(twists[0](0), 0.0205, 1e-6);  // the union's best motion (equal curvatures: the mean)
  EXPECT_NEAR(u.support(0), 200.0, 1e-3);
  EXPECT_NEAR(twists[1](0), -0.03, 1e-9);
  EXPECT_NEAR(st.smallest_refused_merge, 2e5 * 1e5 / 3e5 * 0.0505 * 0.0505, 1e-2);  // parallel sum x d^2 (the 1e-6 ridge shifts it by 3e-4)
  // A higher label cost merges that one too.
  config.label_cost = 1.0;
  model = uniformModel(2, 1e5 * Matrix6d::Identity());
  model.curvature[0] *= 2;
  EXPECT_EQ(adaptLabelCount(u, twists, model, 300, config).merged, 1);
  EXPECT_EQ(u.count, 2);
}

TEST(LabelAdaptation, DirectionsTheDataDoesNotConstrainDoNotKeepLabelsApart) {
  // A rotation about the optical axis that the segments' pixels barely see (tiny curvature there): the
  // twists differ by 3 degrees, yet one motion explains both; the same difference in a constrained
  // direction keeps them apart.
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  Matrix6d H = 1e5 * Matrix6d::Identity();
  H(5, 5) = 1.0;
  Vector6d a = Vector6d::Zero(), b = Vector6d::Zero(), c = Vector6d::Zero();
  b(5) = 0.05;
  c(3) = 0.05;
  std::vector<Vector6d> twists{a, b, c};
  LabelCostModel model = uniformModel(3, H);
  Config config;
  const AdaptationStats st = adaptLabelCount(u, twists, model, 300, config);
  EXPECT_EQ(st.merged, 1);
  ASSERT_EQ(twists.size(), 2u);
  EXPECT_NEAR(twists[1](3), 0.05, 1e-9);
}

TEST(LabelAdaptation, MergedMotionLeansTowardsTheBetterConstrainedLabel) {
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  Vector6d a = Vector6d::Zero(), b = Vector6d::Zero(), c = Vector6d::Zero();
  b(2) = 0.004;
  c(2) = 1.0;
  std::vector<Vector6d> twists{a, b, c};
  LabelCostModel model = uniformModel(3, 100 * Matrix6d::Identity());
  model.curvature[1] *= 3;  // label 1's pixels pin the motion three times as hard
  Config config;
  ASSERT_EQ(adaptLabelCount(u, twists, model, 300, config).merged, 1);
  EXPECT_NEAR(twists[0](2), 0.003, 1e-6);
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
  LabelCostModel model = uniformModel(3, 1e5 * Matrix6d::Identity());
  Config config;
  config.min_support_fraction = 0.05;  // 15 of 300 pixels
  const AdaptationStats st = adaptLabelCount(u, twists, model, 300, config);
  EXPECT_EQ(st.merged, 0);
  EXPECT_EQ(st.removed, 1);
  ASSERT_EQ(u.count, 3);
  EXPECT_NEAR(u.support(u.outlier()), 2.0, 1e-6);
  EXPECT_NEAR(twists[1](2), 0.1, 1e-12);
  EXPECT_EQ(model.curvature.size(), 2u);
}

TEST(LabelAdaptation, MismatchedInputsAreRefused) {
  SoftLabels u;
  ImageF points;
  makeBands(u, points);
  std::vector<Vector6d> twists(2, Vector6d::Zero());
  LabelCostModel model = uniformModel(3, Matrix6d::Identity());
  EXPECT_THROW(adaptLabelCount(u, twists, model, 300, Config()), InputError);
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
