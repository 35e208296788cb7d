// Display colours of segment ids.
#include <gtest/gtest.h>

#include <cmath>

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

}  // namespace
}  // namespace mc_flow
