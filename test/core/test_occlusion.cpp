#include <gtest/gtest.h>

#include <limits>

#include "mc_flow/core/occlusion.h"
#include "mc_flow/core/pyramid.h"

namespace mc_flow {
namespace {

const Intrinsics kCamera{40.0, 40.0, 19.5, 14.5};
constexpr int kW = 40, kH = 30;

bool inSquare(int x, int y, int x0) { return x >= x0 && x < x0 + 8 && y >= 10 && y < 18; }

TEST(Occlusion, ForegroundSquareMovingRightHidesTheBackgroundItCovers) {
  // Frame 1: background plane at 3 m, an 8x8 px square at 1 m (columns 10..17). The square moves right by
  // 4 px (0.1 m at 1 m, fx = 40); the background is static.
  ImageF depth1(kW, kH, 1, 3.f), depth2(kW, kH, 1, 3.f);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (inSquare(x, y, 10)) depth1(x, y) = 1.f;
      if (inSquare(x, y, 14)) depth2(x, y) = 1.f;
    }
  depth1(0, 0) = 0.f;  // one pixel without depth
  ImageF warped = backProject(depth1, kCamera);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x)
      if (inSquare(x, y, 10)) warped(x, y, 0) += 0.1f;

  const Config config;
  const ImageU8 mask = detectOcclusions(warped, depth2, kCamera, config);
  ASSERT_TRUE(mask.sameSize(kW, kH));
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const bool covered_background = !inSquare(x, y, 10) && inSquare(x, y, 14);  // columns 18..21
      if (covered_background)
        EXPECT_EQ(mask(x, y), 255) << "covered background at " << x << "," << y;
      else
        EXPECT_EQ(mask(x, y), 0) << "pixel " << x << "," << y;
    }
}

TEST(Occlusion, PointsLeavingTheImageAreOccluded) {
  // A fronto-parallel plane at 2 m translated by 0.5 m to the right: 10 px at fx = 40.
  ImageF depth(kW, kH, 1, 2.f);
  ImageF warped = backProject(depth, kCamera);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) warped(x, y, 0) += 0.5f;
  warped(5, 5, 0) = warped(5, 5, 1) = warped(5, 5, 2) = std::numeric_limits<float>::quiet_NaN();
  const ImageU8 mask = detectOcclusions(warped, depth, kCamera, Config());
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      if (x == 5 && y == 5)
        EXPECT_EQ(mask(x, y), 0) << "invalid points are never flagged";
      else
        EXPECT_EQ(mask(x, y), x + 10 >= kW ? 255 : 0) << "pixel " << x << "," << y;
    }
}

TEST(Occlusion, DepthTestAloneFlagsPointsBehindTheSurface) {
  // One point warps 0.5 m behind the surface frame 2 sees: C = 1 but 1 + K_z * 0.5 > K_o.
  ImageF depth(kW, kH, 1, 2.f);
  ImageF warped = backProject(depth, kCamera);
  for (int c = 0; c < 3; ++c) warped(20, 15, c) *= 1.25f;  // same ray, 2.5 m
  Config config;
  const ImageU8 mask = detectOcclusions(warped, depth, kCamera, config);
  EXPECT_EQ(mask(20, 15), 255);
  EXPECT_EQ(mask(21, 15), 0);
  config.occlusion_kz = 0.0;  // without the depth term the lone point is not occluded
  EXPECT_EQ(detectOcclusions(warped, depth, kCamera, config)(20, 15), 0);
}

}  // namespace
}  // namespace mc_flow
