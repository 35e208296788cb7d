#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "mc_flow/core/error.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {
namespace {

SoftLabels randomSimplexLabels(int w, int h, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  SoftLabels u(w, h, n);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float sum = 0;
      for (int i = 0; i < n; ++i) sum += (u.at(i, x, y) = unit(rng));
      for (int i = 0; i < n; ++i) u.at(i, x, y) /= sum;
    }
  return u;
}

void expectSimplex(const SoftLabels& u) {
  for (int y = 0; y < u.height; ++y)
    for (int x = 0; x < u.width; ++x) {
      float sum = 0;
      for (int i = 0; i < u.count; ++i) {
        EXPECT_GE(u.at(i, x, y), 0.f);
        sum += u.at(i, x, y);
      }
      EXPECT_NEAR(sum, 1.f, 1e-5f) << "pixel " << x << "," << y;
    }
}

TEST(SoftLabels, DownsamplingPreservesTheSimplex) {
  for (auto [w, h] : {std::pair{16, 12}, std::pair{17, 13}}) {
    const SoftLabels u = randomSimplexLabels(w, h, 5, 3);
    const SoftLabels d = downsampleLabels(u, (w + 1) / 2, (h + 1) / 2);
    EXPECT_EQ(d.width, (w + 1) / 2);
    EXPECT_EQ(d.count, 5);
    expectSimplex(d);
    // A coarse pixel is the mean of its 2x2 block.
    EXPECT_NEAR(d.at(2, 1, 1), 0.25f * (u.at(2, 2, 2) + u.at(2, 3, 2) + u.at(2, 2, 3) + u.at(2, 3, 3)), 1e-6f);
  }
}

TEST(SoftLabels, UpsamplingPreservesTheSimplexAndConstants) {
  const SoftLabels u = randomSimplexLabels(9, 7, 4, 5);
  const SoftLabels up = upsampleLabels(u, 18, 14);
  EXPECT_EQ(up.width, 18);
  EXPECT_EQ(up.height, 14);
  expectSimplex(up);

  SoftLabels constant(5, 4, 3);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 5; ++x) {
      constant.at(0, x, y) = 0.2f;
      constant.at(1, x, y) = 0.5f;
      constant.at(2, x, y) = 0.3f;
    }
  const SoftLabels c2 = upsampleLabels(constant, 11, 9);  // a non-integer ratio too
  for (int y = 0; y < 9; ++y)
    for (int x = 0; x < 11; ++x) EXPECT_NEAR(c2.at(1, x, y), 0.5f, 1e-6f);
}

TEST(SoftLabels, UpsamplingIsPixelCentreAligned) {
  // A horizontal ramp in label 0 (coarse x -> 0.1 x): the fine pixel x maps to coarse (x + 0.5) / 2 - 0.5.
  SoftLabels u(8, 2, 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 8; ++x) {
      u.at(0, x, y) = 0.1f * x;
      u.at(1, x, y) = 1.f - 0.1f * x;
    }
  const SoftLabels up = upsampleLabels(u, 16, 4);
  for (int x = 1; x < 15; ++x) EXPECT_NEAR(up.at(0, x, 1), 0.1f * ((x + 0.5f) / 2.f - 0.5f), 1e-6f) << x;
  EXPECT_NEAR(up.at(0, 0, 0), 0.f, 1e-6f);  // clamped at the border
  EXPECT_NEAR(up.at(0, 15, 0), 0.7f, 1e-6f);
}

TEST(SoftLabels, DownThenUpKeepsPiecewiseConstantLabels) {
  SoftLabels u(16, 16, 3, 0.f);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) u.at(x < 8 ? 0 : 1, x, y) = 1.f;
  const SoftLabels back = upsampleLabels(downsampleLabels(u, 8, 8), 16, 16);
  const ImageI32 arg = back.argmax();
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) EXPECT_EQ(arg(x, y), x < 8 ? 0 : 1);
}

TEST(SoftLabels, SupportAndMergeInto) {
  SoftLabels u(4, 3, 4, 0.f);  // labels 0, 1, 2 + outlier 3
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x) {
      u.at(0, x, y) = 0.5f;
      u.at(1, x, y) = 0.25f;
      u.at(2, x, y) = x == 0 ? 0.25f : 0.f;
      u.at(3, x, y) = x == 0 ? 0.f : 0.25f;
    }
  EXPECT_NEAR(u.support(0), 6.0, 1e-6);
  EXPECT_NEAR(u.support(1), 3.0, 1e-6);
  EXPECT_NEAR(u.support(2), 0.75, 1e-6);
  const double outlier_support = u.support(3);

  u.mergeInto(0, 2);
  ASSERT_EQ(u.count, 3);
  EXPECT_EQ(u.data.size(), std::size_t(4 * 3 * 3));
  EXPECT_NEAR(u.support(0), 3.0, 1e-6);              // former label 1
  EXPECT_NEAR(u.support(1), 6.75, 1e-6);             // former label 2 with label 0 added
  EXPECT_NEAR(u.support(2), outlier_support, 1e-6);  // outlier untouched and still last
  expectSimplex(u);

  u.mergeInto(1, u.outlier());  // moving a label into the outlier label
  EXPECT_EQ(u.count, 2);
  expectSimplex(u);
  EXPECT_THROW(u.mergeInto(u.outlier(), 0), InputError);  // the outlier label cannot be removed
  EXPECT_THROW(u.mergeInto(0, 0), InputError);
}

TEST(SoftLabels, ArgmaxIncludesTheOutlier) {
  SoftLabels u(3, 1, 3, 0.f);
  u.at(0, 0, 0) = 0.6f, u.at(1, 0, 0) = 0.3f, u.at(2, 0, 0) = 0.1f;
  u.at(0, 1, 0) = 0.1f, u.at(1, 1, 0) = 0.7f, u.at(2, 1, 0) = 0.2f;
  u.at(0, 2, 0) = 0.2f, u.at(1, 2, 0) = 0.2f, u.at(2, 2, 0) = 0.6f;
  const ImageI32 a = u.argmax();
  EXPECT_EQ(a(0, 0), 0);
  EXPECT_EQ(a(1, 0), 1);
  EXPECT_EQ(a(2, 0), 2);
}

}  // namespace
}  // namespace mc_flow
