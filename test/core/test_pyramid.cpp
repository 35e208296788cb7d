#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <utility>
#include <vector>
#include <Eigen/Core>
#include <limits>

#include "mc_flow/core/error.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/pyramid_pixel.h"

namespace mc_flow {
namespace {

const Intrinsics kCamera{263.7, 263.7, 159.5, 119.5};

RgbdFrame planeFrame(int w, int h, float z) {
  RgbdFrame f;
  f.intensity = ImageF(w, h, 1, 0.5f);
  f.depth = ImageF(w, h, 1, z);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) f.intensity(x, y) = float((x * 7 + y * 3) % 17) / 16.f;
  return f;
}

TEST(Pyramid, LevelCount) {
  EXPECT_EQ(pyramidLevelCount(320, 240, 20), 5);  // 320 160 80 40 20
  EXPECT_EQ(pyramidLevelCount(640, 480, 20), 6);
  EXPECT_EQ(pyramidLevelCount(319, 240, 20), 4);  // 319 159 79 39 (19 < 20)
  EXPECT_EQ(pyramidLevelCount(20, 15, 20), 1);
  EXPECT_EQ(pyramidLevelCount(10, 10, 20), 1);  // never fewer than one level
}

TEST(Pyramid, BuildsLevelsOfHalvedSizeAndScaledIntrinsics) {
  const Config config;
  const Pyramid p = buildPyramid(planeFrame(320, 240, 2.f), kCamera, 5, config);
  ASSERT_EQ(p.size(), 5);
  for (int l = 0; l < p.size(); ++l) {
    const PyramidLevel& level = p[l];
    EXPECT_EQ(level.intensity.width, 320 >> l);
    EXPECT_EQ(level.depth.height, 240 >> l);
    EXPECT_EQ(level.points.channels, 3);
    EXPECT_EQ(level.intensity_grad.channels, 2);
    EXPECT_EQ(level.depth_grad.channels, 2);
    EXPECT_DOUBLE_EQ(level.intrinsics.fx, kCamera.fx / (1 << l));
    EXPECT_EQ(level.validCount(), (320 >> l) * (240 >> l));
  }
}

TEST(Pyramid, LevelExtentIsTheBuiltLevelSize) {
  const Config config;
  const Pyramid p = buildPyramid(planeFrame(317, 239, 2.f), kCamera, 5, config);
  for (int l = 0; l < p.size(); ++l) {
    EXPECT_EQ(pyramidLevelExtent(317, l), p[l].points.width) << "level " << l;
    EXPECT_EQ(pyramidLevelExtent(239, l), p[l].points.height) << "level " << l;
  }
  EXPECT_EQ(pyramidLevelExtent(317, 3), 39);  // 317 158 79 39
  EXPECT_EQ(pyramidLevelExtent(1, 4), 1);     // never below one pixel
}

TEST(Pyramid, IntrinsicsScalingKeepsProjectionsConsistent) {
  // The same 3D point must project onto the same physical spot: x_l = (x_0 + 0.5) / 2^l - 0.5.
  const Eigen::Vector3d point(0.37, -0.21, 1.9);
  const double x0 = kCamera.fx * point.x() / point.z() + kCamera.cx;
  const double y0 = kCamera.fy * point.y() / point.z() + kCamera.cy;
  for (int l = 1; l < 5; ++l) {
    const Intrinsics K = kCamera.scaled(std::ldexp(1.0, -l));
    const double xl = K.fx * point.x() / point.z() + K.cx, yl = K.fy * point.y() / point.z() + K.cy;
    EXPECT_NEAR(xl, (x0 + 0.5) / (1 << l) - 0.5, 1e-9);
    EXPECT_NEAR(yl, (y0 + 0.5) / (1 << l) - 0.5, 1e-9);
  }
  // And the pyramid's back-projection at a coarse pixel agrees with the fine-level one of the same spot:
  // a fronto-parallel plane at 2 m seen by coarse pixel (10, 7) covers fine pixels 20..21 x 14..15.
  const Config config;
  const Pyramid p = buildPyramid(planeFrame(320, 240, 2.f), kCamera, 3, config);
  const float* coarse = &p[1].points(10, 7, 0);
  const float* fine_a = &p[0].points(20, 14, 0);
  const float* fine_b = &p[0].points(21, 15, 0);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(coarse[c], 0.5f * (fine_a[c] + fine_b[c]), 1e-5f);
}

TEST(Pyramid, DepthDownsampleNeverBlendsAcrossAStepEdge) {
  // Vertical step edge at an odd column so that blocks straddle it: 1 m left, 3 m right.
  const int w = 64, h = 32;
  for (int edge : {21, 22, 23}) {
    ImageF depth(w, h, 1, 0.f);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) depth(x, y) = x < edge ? 1.f : 3.f;
    ImageF level = depth;
    for (int l = 0; l < 3; ++l) {
      level = downsampleDepth(level, 0.1);
      for (float z : level.data) {
        EXPECT_FALSE(z > 1.2f && z < 2.8f) << "blended depth " << z << " at level " << l + 1 << ", edge " << edge;
        EXPECT_TRUE(z == 1.f || z == 3.f) << z;
      }
    }
  }
}

TEST(Pyramid, DepthDownsampleIgnoresInvalidPixels) {
  ImageF depth(8, 8, 1, 2.f);
  depth(2, 2) = 0.f;
  depth(3, 3) = std::numeric_limits<float>::quiet_NaN();
  depth(4, 4) = 0.f;
  const ImageF out = downsampleDepth(depth, 0.1);
  ASSERT_EQ(out.width, 4);
  for (float z : out.data) EXPECT_FLOAT_EQ(z, 2.f);  // not pulled towards 0, never NaN

  // A block that is entirely invalid stays invalid even when its 4x4 neighbourhood is valid.
  ImageF holes(8, 8, 1, 2.f);
  holes(4, 4) = holes(5, 4) = holes(4, 5) = holes(5, 5) = 0.f;
  const ImageF out2 = downsampleDepth(holes, 0.1);
  EXPECT_EQ(out2(2, 2), 0.f);
  EXPECT_FLOAT_EQ(out2(1, 1), 2.f);
}

TEST(Pyramid, DepthDownsampleIsThePerPixelRuleBitForBit) {
  // downsampleDepth runs the interior through its own branch-free copy of pyramid_pixel::downsampledDepth (the
  // rule the CUDA pyramid shares): the same bits on noisy depth with holes, NaN, infinities, negatives and -0, on
  // odd and tiny sizes, for ranges that reject many samples, none, or (NaN) none either way.
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.f, 0.03f);
  std::uniform_int_distribution<int> pick(0, 99);
  const float specials[] = {0.f,
                            -0.f,
                            -1.f,
                            std::numeric_limits<float>::quiet_NaN(),
                            std::numeric_limits<float>::infinity(),
                            -std::numeric_limits<float>::infinity(),
                            std::numeric_limits<float>::max(),
                            std::numeric_limits<float>::denorm_min()};
  for (const auto& [w, h] :
       std::vector<std::pair<int, int>>{{64, 48}, {63, 47}, {37, 5}, {5, 4}, {4, 3}, {2, 2}, {1, 1}}) {
    ImageF depth(w, h, 1, 0.f);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const int p = pick(rng);
        depth(x, y) = p < 8 ? specials[p] : (x < w / 2 ? 1.f : 2.5f) + 0.01f * y + noise(rng);
      }
    for (const double range : {0.1, 0.02, 10.0, std::nan("")}) {
      const ImageF out = downsampleDepth(depth, range);
      const auto at = [&](int x, int y) { return depth(x, y); };
      for (int y = 0; y < out.height; ++y)
        for (int x = 0; x < out.width; ++x) {
          const float expected = pyramid_pixel::downsampledDepth(at, w, h, x, y, float(range));
          std::uint32_t a, b;
          std::memcpy(&a, &out(x, y), 4);
          std::memcpy(&b, &expected, 4);
          ASSERT_EQ(a, b) << w << "x" << h << " range " << range << " at (" << x << ", " << y << "): " << out(x, y)
                          << " vs " << expected;
        }
    }
  }
}

TEST(Pyramid, IntensityDownsampleIsThePerPixelRuleBitForBit) {
  // downsampleIntensity reads one-channel interiors straight from the rows: the same bits as
  // pyramid_pixel::downsampledIntensity (the rule the CUDA pyramid shares), on odd and tiny sizes.
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> value(-0.5f, 1.5f);
  for (const auto& [w, h] :
       std::vector<std::pair<int, int>>{{64, 48}, {63, 47}, {37, 5}, {5, 4}, {4, 3}, {2, 2}, {1, 1}}) {
    for (const int channels : {1, 2}) {
      ImageF image(w, h, channels, 0.f);
      for (float& v : image.data) v = value(rng);
      const ImageF out = downsampleIntensity(image);
      for (int c = 0; c < channels; ++c) {
        const auto at = [&](int x, int y) { return image(x, y, c); };
        for (int y = 0; y < out.height; ++y)
          for (int x = 0; x < out.width; ++x) {
            const float expected = pyramid_pixel::downsampledIntensity(at, w, h, x, y);
            ASSERT_EQ(std::memcmp(&out(x, y, c), &expected, 4), 0)
                << w << "x" << h << "x" << channels << " at (" << x << ", " << y << "): " << out(x, y, c) << " vs "
                << expected;
          }
      }
    }
  }
}

TEST(Pyramid, DepthDownsampleAveragesWithinRange) {
  // A slanted plane (within range everywhere) is averaged with the [1 3 3 1] weights: a linear ramp
  // z = 1 + 0.01 x keeps its value at the block centre (2i + 0.5) away from the borders.
  ImageF depth(16, 16, 1, 0.f);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) depth(x, y) = 1.f + 0.01f * x;
  const ImageF out = downsampleDepth(depth, 0.1);
  for (int x = 1; x < 7; ++x) EXPECT_NEAR(out(x, 3), 1.f + 0.01f * (2 * x + 0.5f), 1e-6f);
}

TEST(Pyramid, BuildCleansDepthOutsideRange) {
  Config config;
  config.min_depth = 0.5;
  config.max_depth = 4.0;
  RgbdFrame f = planeFrame(40, 30, 2.f);
  f.depth(0, 0) = 0.3f;
  f.depth(1, 0) = 4.5f;
  f.depth(2, 0) = std::numeric_limits<float>::quiet_NaN();
  f.depth(3, 0) = -1.f;
  const Pyramid p = buildPyramid(f, kCamera, 2, config);
  for (int x = 0; x < 4; ++x) {
    EXPECT_EQ(p[0].depth(x, 0), 0.f);
    EXPECT_TRUE(std::isnan(p[0].points(x, 0, 2)));
  }
  EXPECT_EQ(p[0].validCount(), 40 * 30 - 4);
  for (float z : p[1].depth.data) EXPECT_FALSE(std::isnan(z));
}

TEST(Pyramid, GradientOfALinearRampIsItsSlope) {
  ImageF ramp(20, 10, 1, 0.f);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 20; ++x) ramp(x, y) = 0.02f * x - 0.03f * y + 0.5f;
  const ImageF g = blendedGradient(ramp, nullptr, 1e-6f);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 20; ++x) {  // borders included: one-sided differences of a ramp are exact too
      EXPECT_NEAR(g(x, y, 0), 0.02f, 1e-6f);
      EXPECT_NEAR(g(x, y, 1), -0.03f, 1e-6f);
    }
}

TEST(Pyramid, BlendedGradientLeansToTheSmallerDifference) {
  // A step: f = 0 for x <= 4, 1 for x >= 5. At x = 4 the backward difference is 0, the forward 1:
  // the blend must stay near 0 instead of the central difference 0.5.
  ImageF step(10, 1, 1, 0.f);
  for (int x = 5; x < 10; ++x) step(x, 0) = 1.f;
  const ImageF g = blendedGradient(step, nullptr, 1e-6f);
  EXPECT_LT(std::fabs(g(4, 0, 0)), 1e-4f);
  EXPECT_LT(std::fabs(g(5, 0, 0)), 1e-4f);
}

TEST(Pyramid, DepthGradientDoesNotUseInvalidNeighbours) {
  ImageF depth(10, 5, 1, 0.f);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 10; ++x) depth(x, y) = 1.f + 0.1f * x;
  for (int y = 0; y < 5; ++y) depth(5, y) = 0.f;  // an invalid column
  const ImageF g = blendedGradient(depth, &depth, 0.005f);
  // Next to the hole the remaining one-sided difference is used, not a jump to 0.
  EXPECT_NEAR(g(4, 2, 0), 0.1f, 1e-5f);
  EXPECT_NEAR(g(6, 2, 0), 0.1f, 1e-5f);
  // The invalid pixel itself has no gradient.
  EXPECT_EQ(g(5, 2, 0), 0.f);
  EXPECT_EQ(g(5, 2, 1), 0.f);
}

TEST(Pyramid, IntensityDownsampleKeepsConstantsAndRamps) {
  ImageF ramp(16, 8, 1, 0.f);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 16; ++x) ramp(x, y) = 0.03f * x;
  const ImageF out = downsampleIntensity(ramp);
  ASSERT_EQ(out.width, 8);
  ASSERT_EQ(out.height, 4);
  // Interior: the symmetric kernel reproduces the ramp at the block centre 2i + 0.5.
  for (int x = 1; x < 7; ++x) EXPECT_NEAR(out(x, 2), 0.03f * (2 * x + 0.5f), 1e-6f);
}

TEST(Pyramid, BackProjectInvertsProjection) {
  ImageF depth(320, 240, 1, 0.f);
  depth(100, 50) = 2.5f;
  const ImageF points = backProject(depth, kCamera);
  const float* p = &points(100, 50, 0);
  EXPECT_NEAR(kCamera.fx * p[0] / p[2] + kCamera.cx, 100.0, 1e-4);
  EXPECT_NEAR(kCamera.fy * p[1] / p[2] + kCamera.cy, 50.0, 1e-4);
  EXPECT_FLOAT_EQ(p[2], 2.5f);
  EXPECT_TRUE(std::isnan(points(0, 0, 0)));
}

}  // namespace
}  // namespace mc_flow
