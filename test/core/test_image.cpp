#include <gtest/gtest.h>

#include <limits>
#include <string>

#include "mc_flow/core/error.h"
#include "mc_flow/core/image.h"

namespace mc_flow {
namespace {

// Expects `f` to throw an InputError whose message contains every one of `needles`.
template <typename F>
void expectInputError(F f, std::initializer_list<std::string> needles) {
  try {
    f();
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    for (const std::string& n : needles) EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << e.what();
  }
}

TEST(Image, IntrinsicsValidate) {
  EXPECT_NO_THROW((Intrinsics{263.7, 263.7, 159.5, 119.5}.validate()));
  expectInputError([] { Intrinsics{0.0, 263.7, 159.5, 119.5}.validate(); }, {"fx"});
  expectInputError([] { Intrinsics{263.7, -5.0, 159.5, 119.5}.validate(); }, {"fy", "-5"});
  expectInputError([] { Intrinsics{263.7, 263.7, std::numeric_limits<double>::infinity(), 119.5}.validate(); }, {"cx"});
  expectInputError([] { Intrinsics{263.7, 263.7, 159.5, std::nan("")}.validate(); }, {"cy"});
  const std::string text = Intrinsics{263.7, 263.5, 159.5, 119.5}.toString();
  EXPECT_NE(text.find("263.7"), std::string::npos);
  EXPECT_NE(text.find("119.5"), std::string::npos);
}

TEST(Image, FrameValidate) {
  RgbdFrame f;
  f.intensity = ImageF(8, 6, 1, 0.5f);
  f.depth = ImageF(8, 6, 1, 1.f);
  EXPECT_NO_THROW(f.validate("frame1"));

  RgbdFrame wrong_size = f;
  wrong_size.depth = ImageF(4, 3, 1, 1.f);
  expectInputError([&] { wrong_size.validate("frame1"); }, {"frame1", "4x3", "8x6"});

  RgbdFrame empty = f;
  empty.intensity = ImageF();
  expectInputError([&] { empty.validate("frame2"); }, {"frame2", "intensity"});

  RgbdFrame nan_intensity = f;
  nan_intensity.intensity(3, 2) = std::numeric_limits<float>::quiet_NaN();
  expectInputError([&] { nan_intensity.validate("frame2"); }, {"frame2", "(3, 2)"});
  for (const float bad : {std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()}) {
    RgbdFrame infinite_intensity = f;
    infinite_intensity.intensity(7, 5) = bad;  // the last pixel: the fast pass and the search both reach it
    expectInputError([&] { infinite_intensity.validate("frame1"); }, {"frame1", "(7, 5)"});
  }

  RgbdFrame no_depth = f;
  for (float& z : no_depth.depth.data) z = 0.f;
  no_depth.depth(1, 1) = std::numeric_limits<float>::quiet_NaN();
  expectInputError([&] { no_depth.validate("frame2"); }, {"frame2", "no valid depth"});

  RgbdFrame one_valid = no_depth;
  one_valid.depth(5, 5) = 2.f;
  EXPECT_NO_THROW(one_valid.validate("frame2"));
}

}  // namespace
}  // namespace mc_flow
