// Display colours of segment ids.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/core/palette.h"

namespace mc_flow {
namespace {

TEST(Palette, ColoursAreStableAndDistinct) {
  EXPECT_EQ(colourForId(0).r, colourForId(0).g);  // grey for the outlier
  for (std::uint32_t a = 1; a <= 12; ++a) {
    const auto ca = colourForId(a);
    const auto again = colourForId(a);
    EXPECT_EQ(ca.r, again.r);
    EXPECT_EQ(ca.g, again.g);
    EXPECT_EQ(ca.b, again.b);
    for (std::uint32_t b = a + 1; b <= 12; ++b) {
      const auto cb = colourForId(b);
      const double distance = std::sqrt(std::pow(ca.r - cb.r, 2) + std::pow(ca.g - cb.g, 2) + std::pow(ca.b - cb.b, 2));
      EXPECT_GT(distance, 25.0) << "ids " << a << " and " << b << " look alike";
    }
  }
}

TEST(Palette, SegmentationPictureBlendsSegmentColoursOverTheImage) {
  SoftLabels u(2, 1, 3, 0.f);  // two segments + outlier
  u.at(0, 0, 0) = 0.75f;
  u.at(2, 0, 0) = 0.25f;  // pixel 0: 3/4 segment id 7, 1/4 outlier
  u.at(1, 1, 0) = 1.f;    // pixel 1: segment id 3
  const ImageF grey(2, 1, 1, 0.2f);
  const ImageU8 picture = segmentationPicture(u, {7, 3}, &grey, 0.6);
  ASSERT_EQ(picture.channels, 3);
  const Rgb8 c7 = colourForId(7), c0 = colourForId(0), c3 = colourForId(3);
  EXPECT_NEAR(picture(0, 0, 0), 0.6 * (0.75 * c7.r + 0.25 * c0.r) + 0.4 * 51.0, 1.0);
  EXPECT_NEAR(picture(0, 0, 2), 0.6 * (0.75 * c7.b + 0.25 * c0.b) + 0.4 * 51.0, 1.0);
  EXPECT_NEAR(picture(1, 0, 1), 0.6 * c3.g + 0.4 * 51.0, 1.0);
  // Without an image (or with one of another size): mid grey.
  const ImageU8 no_image = segmentationPicture(u, {7, 3}, nullptr, 0.6);
  EXPECT_NEAR(no_image(1, 0, 1), 0.6 * c3.g + 0.4 * 128.0, 1.0);
  EXPECT_THROW(segmentationPicture(u, {7}, &grey, 0.6), InputError);
}

TEST(Palette, SegmentationPictureRoundsAsLroundDoes) {
  // Each channel is std::lround of the clamped blend, halves away from zero (the picture rounds without the
  // library call): random soft labels and greys, and exact halves (blend 0.5 over grey 0 and 255). 67 columns: the
  // rows' 8-pixel blocks (AVX2 where the CPU has it) and their 3-pixel tail; some weights negative or NaN (no share).
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  const int w = 67, h = 8, segments = 5;
  SoftLabels u(w, h, segments + 1, 0.f);
  ImageF grey(w, h, 1, 0.f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (y < 2) {  // one label per pixel, grey 0 or 1: 0.5 * colour (+ 127.5) is a half for odd (even) colours
        u.at(x % (segments + 1), x, y) = 1.f;
        grey(x, y) = float(y);
        continue;
      }
      float sum = 0.f;
      for (int i = 0; i <= segments; ++i) sum += (u.at(i, x, y) = unit(rng));
      for (int i = 0; i <= segments; ++i) u.at(i, x, y) /= sum;
      if ((x + y) % 7 == 0) u.at(x % segments, x, y) = (x % 2 == 0) ? std::nanf("") : -0.25f;
      grey(x, y) = unit(rng) * 1.2f - 0.1f;  // also outside [0, 1]
    }
  const std::vector<int> ids = {1, 2, 3, 4, 5};
  for (const double blend : {0.5, 0.6, 1.0, 1.3}) {
    const ImageU8 picture = segmentationPicture(u, ids, &grey, blend);
    int halves = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c) {
          double mixed = 0;
          for (int i = 0; i <= segments; ++i) {
            const double weight = u.at(i, x, y);
            if (!(weight > 0)) continue;
            const Rgb8 colour = colourForId(std::uint32_t(i < segments ? ids[std::size_t(i)] : 0));
            mixed += weight * (c == 0 ? colour.r : c == 1 ? colour.g : colour.b);
          }
          const double g = 255.0 * std::clamp(double(grey(x, y)), 0.0, 1.0);
          const double value = std::clamp(blend * mixed + (1 - blend) * g, 0.0, 255.0);
          halves += value - std::floor(value) == 0.5 ? 1 : 0;
          ASSERT_EQ(int(picture(x, y, c)), int(std::lround(value))) << "blend " << blend << " at " << x << "," << y;
        }
    if (blend == 0.5) EXPECT_GT(halves, 20);
  }
}

}  // namespace
}  // namespace mc_flow
