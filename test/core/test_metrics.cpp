#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include <Eigen/Geometry>

#include "mc_flow/core/error.h"
#include "mc_flow/eval/metrics.h"

namespace mc_flow {
namespace {

const Intrinsics kCamera{60.0, 60.0, 19.5, 14.5};
constexpr float kNan = std::numeric_limits<float>::quiet_NaN();

TEST(Metrics, EndPointAndAngularErrors) {
  ImageF estimate(4, 1, 2, 0.f), truth(4, 1, 2, 0.f);
  estimate(0, 0, 0) = 1.f;                           // EPE 1, angle between (1,0,1) and (0,0,1) = 45 deg
  estimate(1, 0, 0) = 3.f, estimate(1, 0, 1) = 4.f;  // EPE 5 (excluded below in the second check)
  truth(2, 0, 0) = 2.f, estimate(2, 0, 0) = 2.f;     // exact: 0
  estimate(3, 0, 0) = kNan;                          // skipped
  ImageU8 none(4, 1, 1, 0);
  const FlowErrors all = opticalFlowErrors(estimate, truth, nullptr);
  EXPECT_EQ(all.pixels, 3u);
  EXPECT_NEAR(all.epe, (1.0 + 5.0 + 0.0) / 3.0, 1e-9);
  const double angle1 = 45.0;
  const double angle2 = std::acos(1.0 / std::sqrt(26.0)) * 180.0 / M_PI;
  EXPECT_NEAR(all.aae_deg, (angle1 + angle2) / 3.0, 1e-9);
  EXPECT_EQ(opticalFlowErrors(estimate, truth, &none).pixels, 3u);

  ImageU8 excluded(4, 1, 1, 0);
  excluded(1, 0) = 255;
  const FlowErrors some = opticalFlowErrors(estimate, truth, &excluded);
  EXPECT_EQ(some.pixels, 2u);
  EXPECT_NEAR(some.epe, 0.5, 1e-9);
  EXPECT_NEAR(some.aae_deg, 22.5, 1e-9);
}

TEST(Metrics, SceneFlowEndPointError) {
  ImageF estimate(2, 1, 3, 0.f), truth(2, 1, 3, 0.f);
  estimate(0, 0, 2) = 0.03f, estimate(0, 0, 1) = 0.04f;  // 5 cm
  truth(1, 0, 0) = kNan;
  std::size_t pixels = 0;
  EXPECT_NEAR(sceneFlowEpe(estimate, truth, nullptr, &pixels), 0.05, 1e-7);
  EXPECT_EQ(pixels, 1u);
}

// A textured fronto-parallel plane at 2 m; frame 2 is frame 1 shifted right by `shift_px` pixels.
void shiftedPair(int shift_px, RgbdFrame& f1, RgbdFrame& f2) {
  const int w = 40, h = 30;
  auto texture = [](double x, double y) { return float(0.5 + 0.3 * std::sin(0.7 * x) * std::cos(0.4 * y)); };
  f1.intensity = ImageF(w, h, 1, 0.f);
  f2.intensity = ImageF(w, h, 1, 0.f);
  f1.depth = ImageF(w, h, 1, 2.f);
  f2.depth = ImageF(w, h, 1, 2.f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      f1.intensity(x, y) = texture(x, y);
      f2.intensity(x, y) = texture(x - shift_px, y);
    }
  f1.depth(0, 0) = 0.f;
}

TEST(Metrics, ZeroFlowOnIdenticalFramesHasZeroResidual) {
  RgbdFrame f1, f2;
  shiftedPair(0, f1, f2);
  const ResidualRmse r = warpResidualRmse(f1, f2, kCamera, nullptr, nullptr);
  EXPECT_EQ(r.pixels, std::size_t(40 * 30 - 1));
  EXPECT_NEAR(r.photometric, 0.0, 1e-7);
  EXPECT_NEAR(r.geometric, 0.0, 1e-7);
}

TEST(Metrics, CorrectFlowExplainsAShift) {
  RgbdFrame f1, f2;
  shiftedPair(3, f1, f2);
  const ResidualRmse zero = warpResidualRmse(f1, f2, kCamera, nullptr, nullptr);
  EXPECT_GT(zero.photometric, 0.05);

  ImageF flow(40, 30, 3, 0.f);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) flow(x, y, 0) = float(3.0 * 2.0 / kCamera.fx);  // 3 px at 2 m
  ImageU8 excluded(40, 30, 1, 0);
  excluded(10, 10) = 1;
  const ResidualRmse right = warpResidualRmse(f1, f2, kCamera, &flow, &excluded);
  EXPECT_LT(right.photometric, 1e-5);
  EXPECT_LT(right.geometric, 1e-5);
  // Pixels that land outside frame 2 (the last 3 columns), the excluded one and the one without depth drop out.
  EXPECT_EQ(right.pixels, std::size_t(37 * 30 - 2));

  // A depth change is a geometric residual: frame 2 seen 0.1 m further away.
  for (float& z : f2.depth.data) z += 0.1f;
  EXPECT_NEAR(warpResidualRmse(f1, f2, kCamera, &flow, nullptr).geometric, 0.1, 1e-5);
}

TEST(Metrics, SegmentationAgreementIsInvariantToIds) {
  ImageI32 truth(6, 1, 1, 0), estimate(6, 1, 1, 0);
  const int t[6] = {0, 0, 1, 1, 2, 2};
  const int e[6] = {5, 5, 0, 0, 9, 9};  // a permutation of the ids
  for (int x = 0; x < 6; ++x) truth(x, 0) = t[x], estimate(x, 0) = e[x];
  EXPECT_DOUBLE_EQ(segmentationAgreement(estimate, truth), 1.0);
  estimate(5, 0) = 5;  // one pixel joins the wrong segment
  EXPECT_DOUBLE_EQ(segmentationAgreement(estimate, truth), 5.0 / 6.0);
  estimate(5, 0) = -1;  // invalid pixels do not count
  EXPECT_DOUBLE_EQ(segmentationAgreement(estimate, truth), 1.0);
  // One estimated segment covering two parts can match only one of them.
  for (int x = 0; x < 6; ++x) estimate(x, 0) = 0;
  EXPECT_DOUBLE_EQ(segmentationAgreement(estimate, truth), 2.0 / 6.0);
}

TEST(Metrics, MaskAgreement) {
  ImageU8 a(4, 1, 1, 0), b(4, 1, 1, 0), valid(4, 1, 1, 1);
  a(0, 0) = 255, b(0, 0) = 1;  // both set (any non-zero)
  a(1, 0) = 255;               // disagree
  valid(1, 0) = 0;
  EXPECT_DOUBLE_EQ(maskAgreement(a, b, nullptr), 0.75);
  EXPECT_DOUBLE_EQ(maskAgreement(a, b, &valid), 1.0);
}

TEST(Metrics, MaskIouAndTheOverlapOfSegmentsWithAPart) {
  // Truth: part 0 on the left 6 pixels, part 1 on the right 2. Estimate: segments 3 and 4 on the left 5 pixels, the
  // segment 7 on the rest (one part-0 pixel and both part-1 pixels), and one outlier (0).
  ImageI32 truth(8, 1, 1, 0), labels(8, 1, 1, 0);
  const int t[8] = {0, 0, 0, 0, 0, 0, 1, 1};
  const int e[8] = {3, 3, 4, 4, 0, 7, 7, 7};
  for (int x = 0; x < 8; ++x) truth(x, 0) = t[x], labels(x, 0) = e[x];
  const RegionOverlap world = regionOverlap(labels, {3, 4}, truth, 0, nullptr);
  EXPECT_EQ(world.estimate, 4u);
  EXPECT_EQ(world.truth, 6u);
  EXPECT_EQ(world.common, 4u);
  EXPECT_DOUBLE_EQ(world.coverage(), 4.0 / 6.0);
  EXPECT_DOUBLE_EQ(world.purity(), 1.0);
  EXPECT_TRUE(world.matches());
  // The segment 7 is mostly part 1 and covers a sixth of part 0: not part 0's segment.
  EXPECT_FALSE(regionOverlap(labels, {7}, truth, 0, nullptr).matches());
  // Together they cover 5 of 6 part-0 pixels, but 2 of their 7 pixels are part 1: still part 0 (5/7 > 1/2).
  EXPECT_TRUE(regionOverlap(labels, {3, 4, 7}, truth, 0, nullptr).matches());
  // Invalid pixels do not count: without the left four, segments 3 and 4 are empty.
  ImageU8 valid(8, 1, 1, 1);
  for (int x = 0; x < 4; ++x) valid(x, 0) = 0;
  const RegionOverlap none = regionOverlap(labels, {3, 4}, truth, 0, &valid);
  EXPECT_EQ(none.estimate, 0u);
  EXPECT_FALSE(none.matches());

  ImageU8 a(8, 1, 1, 0), b(8, 1, 1, 0);
  EXPECT_DOUBLE_EQ(maskIou(a, b, nullptr), 1.0);  // both empty: they agree
  a(5, 0) = a(6, 0) = a(7, 0) = 255;
  b(6, 0) = b(7, 0) = 1;
  EXPECT_DOUBLE_EQ(maskIou(a, b, nullptr), 2.0 / 3.0);
  valid(5, 0) = 0;
  EXPECT_DOUBLE_EQ(maskIou(a, b, &valid), 1.0);
  EXPECT_THROW(maskIou(a, ImageU8(7, 1, 1, 0), nullptr), InputError);
}

TEST(Metrics, NeesAndChiSquareQuantiles) {
  // Tabulated quantiles (6 degrees of freedom: the 95% interval of a twist's NEES) and a closed form (2: -2 ln(1 - p)).
  EXPECT_NEAR(chiSquareQuantile(6, 0.025), 1.2373, 1e-4);
  EXPECT_NEAR(chiSquareQuantile(6, 0.975), 14.4494, 1e-4);
  EXPECT_NEAR(chiSquareQuantile(2, 0.95), -2.0 * std::log(0.05), 1e-8);
  EXPECT_NEAR(chiSquareQuantile(180, 0.975), 219.0443, 1e-3);  // the mean of 30 six-dof NEES: 7.30 at most
  EXPECT_THROW(chiSquareQuantile(0, 0.5), InputError);
  EXPECT_THROW(chiSquareQuantile(6, 1.0), InputError);
  // e^T C^-1 e with a diagonal C: the squared errors in standard deviations.
  Matrix6d covariance = Matrix6d::Zero();
  covariance.diagonal() << 1e-6, 1e-6, 4e-6, 1e-4, 1e-4, 1e-4;
  Vector6d error = Vector6d::Zero();
  error << 1e-3, 0, 4e-3, 0, 0, 2e-2;
  EXPECT_NEAR(nees(error, covariance), 1.0 + 4.0 + 4.0, 1e-9);
}

TEST(Metrics, TheAbsoluteTrajectoryErrorOfAKnownTrajectory) {
  // A straight path of 5 poses, 10 cm apart along x; the estimate is it in another frame (rotated and shifted), one
  // pose 4 cm off along y. The rigid alignment cannot undo that: ATE = sqrt(sum of squared residuals / 5) of the best
  // fit, which moves the line by 4/5 cm towards the outlier: residuals 0.8 cm (x4) and 3.2 cm.
  StampedPoses truth, estimate;
  Eigen::Matrix4d frame = Eigen::Matrix4d::Identity();
  frame.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  frame.topRightCorner<3, 1>() = Eigen::Vector3d(1, -2, 0.5);
  for (int i = 0; i < 5; ++i) {
    Eigen::Matrix4d p = Eigen::Matrix4d::Identity();
    p(0, 3) = 0.1 * i;
    truth.emplace_back(i / 30.0, p);
    if (i == 2) p(1, 3) += 0.04;
    estimate.emplace_back(i / 30.0, frame * p);
  }
  const TrajectoryErrors e = evaluateTrajectory(truth, estimate, 1e-3, 0.0);
  EXPECT_EQ(e.matched, 5);
  EXPECT_NEAR(e.ate_rmse_m, std::sqrt((4 * 0.008 * 0.008 + 0.032 * 0.032) / 5), 1e-6);
  EXPECT_EQ(e.rpe_frame_pairs, 4);
  EXPECT_NEAR(e.rpe_frame_trans_m, 0.04 * std::sqrt(2.0 / 4.0), 1e-9);  // the outlier's two steps, 4 cm each
  EXPECT_NEAR(e.rpe_frame_rot_deg, 0.0, 1e-5);
  EXPECT_THROW(evaluateTrajectory(truth, estimate, 1e-3, 1.0), InputError);  // nothing matches
}

TEST(Metrics, OdometryConsistencyIsTheNeesOfEachStepAgainstTheTruth) {
  // The camera turns and moves along a known path (ground truth every 10 ms); the odometry's steps (every 30 ms) are
  // the true motions plus known errors, each with a diagonal covariance: NEES = the squared errors in standard
  // deviations.
  StampedPoses truth;
  Vector6d velocity;
  velocity << 0.3, -0.1, 0.2, 0.2, 0.5, -0.1;  // [m/s, rad/s]
  // The path starts away from the world's origin (start): the step is G1^-1 G2 in the camera's frame, not G2 G1^-1.
  Vector6d start_twist;
  start_twist << 1.0, -0.5, 2.0, 0.3, -1.2, 0.7;
  const Eigen::Matrix4d start = se3Exp(start_twist);
  for (int k = 0; k <= 100; ++k) truth.emplace_back(0.01 * k, start * se3Exp(Vector6d(velocity * 0.01 * k)));
  Matrix6d covariance = Matrix6d::Zero();
  covariance.diagonal() << 1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4;
  std::vector<OdometryStep> steps;
  const double errors[4] = {1e-3, 2e-3, 3e-3, 4e-3};  // along x: NEES 1, 4, 9, 16
  for (int i = 0; i < 4; ++i) {
    OdometryStep step;
    step.first = 0.03 * i;
    step.second = 0.03 * (i + 1);
    step.twist = velocity * 0.03;  // a constant velocity: the true step is this twist exactly
    step.twist(0) += errors[i];
    step.covariance = covariance;
    steps.push_back(step);
  }
  OdometryStep unmatched = steps[0];  // no ground truth near 5 s: left out
  unmatched.first = 5.0;
  unmatched.second = 5.03;
  steps.push_back(unmatched);
  const OdometryConsistency c = odometryConsistency(truth, steps, 0.002, 0.0);
  EXPECT_EQ(c.matched, 4);
  EXPECT_NEAR(c.nees_mean, (1.0 + 4.0 + 9.0 + 16.0) / 4.0, 1e-6);
  EXPECT_NEAR(c.nees_median, 9.0, 1e-6);  // median(): the upper middle of an even count
  EXPECT_DOUBLE_EQ(c.inside95, 0.5);      // 4 and 9 lie in [1.24, 14.45]; 1 and 16 do not
  EXPECT_NEAR(c.mean_low, chiSquareQuantile(24, 0.025) / 4.0, 1e-9);
  EXPECT_NEAR(c.mean_high, chiSquareQuantile(24, 0.975) / 4.0, 1e-9);
  // A time offset moves the steps' stamps onto the truth's: steps 1 s late match with offset -1.
  std::vector<OdometryStep> late = steps;
  late.pop_back();
  for (OdometryStep& s : late) s.first += 1.0, s.second += 1.0;
  EXPECT_NEAR(odometryConsistency(truth, late, 0.002, -1.0).nees_mean, 7.5, 1e-6);
  EXPECT_THROW(odometryConsistency(truth, late, 0.002, 0.0), InputError);  // none matches
  std::vector<OdometryStep> bad = {steps[0]};
  bad[0].covariance(0, 0) = -1.0;
  EXPECT_THROW(odometryConsistency(truth, bad, 0.002, 0.0), InputError);
}

}  // namespace
}  // namespace mc_flow

// The nearest-rank percentile the benchmarks print (p90): rank ceil(q n) of the sorted values.
TEST(Metrics, PercentileIsTheNearestRank) {
  const std::vector<double> ten = {10, 9, 8, 7, 6, 5, 4, 3, 2, 1};
  EXPECT_EQ(mc_flow::percentile(ten, 0.9), 9.0);
  EXPECT_EQ(mc_flow::percentile(ten, 0.91), 10.0);
  EXPECT_EQ(mc_flow::percentile(ten, 1.0), 10.0);
  EXPECT_EQ(mc_flow::percentile(ten, 0.5), 5.0);
  EXPECT_EQ(mc_flow::percentile(ten, 0.01), 1.0);
  EXPECT_EQ(mc_flow::percentile({4.0, 1.0, 3.0}, 0.9), 4.0);
  EXPECT_EQ(mc_flow::percentile({7.5}, 0.9), 7.5);
  EXPECT_EQ(mc_flow::percentile({}, 0.9), 0.0);
}
