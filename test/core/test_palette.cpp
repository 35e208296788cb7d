// Display colours of segment ids.
#include <gtest/gtest.h>

#include <cmath>

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

}  // namespace
}  // namespace mc_flow
