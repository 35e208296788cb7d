#include <gtest/gtest.h>

#include <cmath>

#include "mc_flow/core/error.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/scene_flow.h"

namespace mc_flow {
namespace {

const Intrinsics kCamera{50.0, 50.0, 15.5, 11.5};
constexpr int kW = 32, kH = 24;

Vector6d twist(double vx, double vy, double vz, double wx, double wy, double wz) {
  Vector6d xi;
  xi << vx, vy, vz, wx, wy, wz;
  return xi;
}

ImageF slantedPlanePoints() {
  ImageF depth(kW, kH, 1, 0.f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) depth(x, y) = 1.5f + 0.02f * x + 0.01f * y;
  depth(3, 3) = 0.f;
  return backProject(depth, kCamera);
}

Eigen::Vector3d pointAt(const ImageF& points, int x, int y) {
  return Eigen::Vector3d(points(x, y, 0), points(x, y, 1), points(x, y, 2));
}

Eigen::Vector3d transformed(const Eigen::Matrix4d& T, const Eigen::Vector3d& p) {
  return T.topLeftCorner<3, 3>() * p + T.topRightCorner<3, 1>();
}

const std::vector<Vector6d> kTwists = {twist(0.05, -0.02, 0.1, 0.02, -0.05, 0.01),
                                       twist(-0.1, 0.0, 0.03, 0.0, 0.08, -0.03)};

TEST(SceneFlow, OneHotLabelsGiveEachLabelsRigidMotion) {
  const ImageF points = slantedPlanePoints();
  SoftLabels u(kW, kH, 3, 0.f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) u.at(x < kW / 2 ? 0 : 1, x, y) = 1.f;
  const ImageF warped = warpPoints(points, u, kTwists);
  ImageF scene, optical;
  sceneAndOpticalFlow(points, warped, kCamera, scene, optical);
  ASSERT_EQ(scene.channels, 3);
  ASSERT_EQ(optical.channels, 2);
  const Eigen::Matrix4d T[2] = {se3Exp(kTwists[0]), se3Exp(kTwists[1])};
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (x == 3 && y == 3) {
        EXPECT_TRUE(std::isnan(scene(x, y, 0)) && std::isnan(optical(x, y, 1)));
        continue;
      }
      const Eigen::Vector3d P = pointAt(points, x, y);
      const Eigen::Vector3d P2 = transformed(T[x < kW / 2 ? 0 : 1], P);
      const Eigen::Vector3d expected = P2 - P;  // (T - I) P
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(scene(x, y, c), expected[c], 1e-5) << x << "," << y;
      EXPECT_NEAR(optical(x, y, 0), kCamera.fx * P2.x() / P2.z() + kCamera.cx - x, 1e-3);
      EXPECT_NEAR(optical(x, y, 1), kCamera.fy * P2.y() / P2.z() + kCamera.cy - y, 1e-3);
    }
}

TEST(SceneFlow, SoftLabelsInterpolateTheTwists) {
  const ImageF points = slantedPlanePoints();
  SoftLabels u(kW, kH, 3, 0.f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      // 50/50 between the two motion labels; the right half also carries outlier mass, which the
      // renormalisation over motion labels must ignore.
      const float outlier = x < kW / 2 ? 0.f : 0.6f;
      u.at(0, x, y) = u.at(1, x, y) = 0.5f * (1.f - outlier);
      u.at(2, x, y) = outlier;
    }
  const Vector6d mean = 0.5 * (kTwists[0] + kTwists[1]);
  const ImageF warped = warpPoints(points, u, kTwists);
  const Eigen::Matrix4d T = se3Exp(mean);
  for (int y = 0; y < kH; y += 5)
    for (int x = 0; x < kW; x += 3) {
      if (x == 3 && y == 3) continue;
      const Eigen::Vector3d expected = transformed(T, pointAt(points, x, y));
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(warped(x, y, c), expected[c], 1e-5);
    }
}

// A pixel with (almost) no motion-label mass moves rigidly with its largest motion label, the first on ties; the
// renormalised weights of such a pixel would be noise.
TEST(SceneFlow, OutlierPixelsMoveWithTheirLargestMotionLabel) {
  const ImageF points = slantedPlanePoints();
  SoftLabels u(kW, kH, 3, 0.f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) u.at(2, x, y) = 1.f;  // all outlier: ties, label 0
  u.at(1, 5, 1) = 0.0005f, u.at(2, 5, 1) = 0.9995f;    // below the motion-mass threshold: label 1
  u.at(1, 6, 1) = 0.5f, u.at(2, 6, 1) = 0.5f;          // enough mass: label 1's motion, renormalised
  const ImageF warped = warpPoints(points, u, kTwists);
  auto expectMovedBy = [&](int x, int y, const Vector6d& xi) {
    const Eigen::Vector3d expected = transformed(se3Exp(xi), pointAt(points, x, y));
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(warped(x, y, c), expected[c], 1e-5) << x << "," << y;
  };
  expectMovedBy(0, 0, kTwists[0]);
  expectMovedBy(5, 1, kTwists[1]);
  expectMovedBy(6, 1, kTwists[1]);
}

TEST(SceneFlow, RejectsMismatchedTwists) {
  const SoftLabels u(4, 4, 3, 1.f / 3);
  EXPECT_THROW(warpPoints(ImageF(4, 4, 3), u, {kTwists[0]}), InputError);
  EXPECT_THROW(warpPoints(ImageF(4, 4, 3), SoftLabels(4, 4, 0, 0.f), {}), InputError);
}

}  // namespace
}  // namespace mc_flow
