// Validation of incoming messages: every header that is not exactly consistent is refused before any
// library reads the buffer; every consistent one converts without crashing. Random and adversarial
// headers for each supported encoding (the nodelet-manager crash of issue 13 among them). This file is
// also built with ASan+UBSan (test_message_validation_sanitized).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "mc_flow/ros/conversions.h"
#include "mc_flow/ros/message_validation.h"

using mc_flow_ros::FrameInputError;
using mc_flow_ros::ImageRole;
using mc_flow_ros::InputProblem;

namespace {

struct EncodingCase {
  std::string name;
  ImageRole role;
  std::uint64_t value_bytes, channels;
};

const std::vector<EncodingCase> kEncodings = {
    {"rgb8", ImageRole::Colour, 1, 3},  {"bgr8", ImageRole::Colour, 1, 3},  {"rgba8", ImageRole::Colour, 1, 4},
    {"bgra8", ImageRole::Colour, 1, 4}, {"mono8", ImageRole::Colour, 1, 1}, {"mono16", ImageRole::Colour, 2, 1},
    {"16UC1", ImageRole::Depth, 2, 1},  {"32FC1", ImageRole::Depth, 4, 1},
};

constexpr std::uint64_t kMaxPixels = 4096ull * 4096ull;

/// The rule, written independently of the implementation in 128-bit arithmetic.
bool exactlyConsistent(const sensor_msgs::Image& m, const EncodingCase& e) {
  using u128 = unsigned __int128;
  if (m.width == 0 || m.height == 0 || m.step == 0 || m.is_bigendian > 1) return false;
  if (u128(m.width) * m.height > kMaxPixels) return false;
  if (u128(m.step) < u128(m.width) * e.channels * e.value_bytes) return false;
  if (m.step % e.value_bytes != 0) return false;
  return u128(m.height) * m.step == u128(m.data.size());
}

sensor_msgs::Image header(const EncodingCase& e, std::uint32_t w, std::uint32_t h, std::uint32_t step,
                          std::size_t bytes) {
  sensor_msgs::Image m;
  m.header.frame_id = "cam";
  m.encoding = e.name;
  m.width = w;
  m.height = h;
  m.step = step;
  m.data.assign(bytes, 0x40);  // 0x4040 mm, 0x40404040 = 3.0 m: valid depth in both encodings
  return m;
}

/// A valid partner for `image` (the other role, same size) and camera_info, so that the conversion runs.
sensor_msgs::Image partnerOf(const sensor_msgs::Image& image, ImageRole role) {
  const EncodingCase& e = role == ImageRole::Colour ? kEncodings[6] : kEncodings[0];
  const std::uint32_t step = std::uint32_t(image.width * e.channels * e.value_bytes);
  return header(e, image.width, image.height, step, std::size_t(step) * image.height);
}

sensor_msgs::CameraInfo cameraInfo(std::uint32_t w, std::uint32_t h) {
  sensor_msgs::CameraInfo info;
  info.width = w;
  info.height = h;
  info.K = {100, 0, w / 2.0, 0, 100, h / 2.0, 0, 0, 1};
  info.P = {100, 0, w / 2.0, 0, 0, 100, h / 2.0, 0, 0, 0, 1, 0};
  return info;
}

/// Validation must agree with the rule; an accepted small image must also convert (or be refused by name).
void checkOne(const sensor_msgs::Image& m, const EncodingCase& e) {
  const bool expected = exactlyConsistent(m, e);
  bool accepted = true;
  std::string why;
  try {
    mc_flow_ros::validateImage(m, e.role, kMaxPixels);
  } catch (const FrameInputError& error) {
    accepted = false;
    why = error.what();
    EXPECT_TRUE(error.problem == InputProblem::Layout || error.problem == InputProblem::Size) << why;
  }
  ASSERT_EQ(accepted, expected) << e.name << " " << m.width << "x" << m.height << " step " << m.step << " data "
                                << m.data.size() << " is_bigendian " << int(m.is_bigendian) << ": " << why;
  if (!accepted || std::uint64_t(m.width) * m.height > 256 * 256) return;
  const sensor_msgs::Image partner = partnerOf(m, e.role);
  const sensor_msgs::Image& rgb = e.role == ImageRole::Colour ? m : partner;
  const sensor_msgs::Image& depth = e.role == ImageRole::Colour ? partner : m;
  try {
    const auto input = mc_flow_ros::toFrameInput(rgb, depth, cameraInfo(m.width, m.height), 1, kMaxPixels);
    EXPECT_EQ(input.frame.depth.width, int(m.width));
  } catch (const FrameInputError&) {
    // e.g. too small to process: refused by name, which is fine
  }
}

}  // namespace

TEST(MessageValidation, TheWarningKeyOfAProblemIgnoresItsNumbers) {
  const FrameInputError small(InputProblem::Size, "image 8x6 is smaller than 16x12");
  const FrameInputError smaller(InputProblem::Size, "image 4x3 is smaller than 16x12");
  EXPECT_EQ(mc_flow_ros::inputWarningKey(small), "size:image x is smaller than x");
  EXPECT_EQ(mc_flow_ros::inputWarningKey(small), mc_flow_ros::inputWarningKey(smaller));
  // Another problem with the same words is another key.
  EXPECT_NE(mc_flow_ros::inputWarningKey(FrameInputError(InputProblem::Layout, "image 8x6 is smaller than 16x12")),
            mc_flow_ros::inputWarningKey(small));
}

TEST(MessageValidation, TheReportedCrashIsRefusedByName) {
  // 16UC1 5461x4096, step 1048578: 4096 * 1048578 = 2^32 + 8192, and 8192 bytes of data.
  const sensor_msgs::Image depth = header(kEncodings[6], 5461, 4096, 1048578, 8192);
  try {
    mc_flow_ros::toFrameInput(partnerOf(depth, ImageRole::Depth), depth, cameraInfo(5461, 4096), 0);
    FAIL() << "accepted";
  } catch (const FrameInputError& e) {
    EXPECT_EQ(int(e.problem), int(InputProblem::Layout));
    EXPECT_NE(std::string(e.what()).find("4294975488 bytes, but 8192 bytes"), std::string::npos) << e.what();
  }
}

TEST(MessageValidation, OddStepIsALayoutProblemNamingTheStep) {
  const sensor_msgs::Image depth = header(kEncodings[6], 64, 48, 129, 129 * 48);
  try {
    mc_flow_ros::validateImage(depth, ImageRole::Depth);
    FAIL() << "accepted";
  } catch (const FrameInputError& e) {
    EXPECT_EQ(int(e.problem), int(InputProblem::Layout));
    EXPECT_NE(std::string(e.what()).find("step 129 bytes is not a multiple of the 2-byte value size"),
              std::string::npos)
        << e.what();
  }
}

TEST(MessageValidation, WrapsOfHeightTimesStepAroundTwoToThe32AreRefusedForEveryEncoding) {
  for (const EncodingCase& e : kEncodings) {
    SCOPED_TRACE(e.name);
    const std::uint64_t pixel = e.channels * e.value_bytes;
    for (std::uint32_t height : {2u, 3u, 4096u, 65536u, 65537u}) {
      for (std::uint64_t extra : {0ull, 1ull, 8192ull, 100000ull}) {
        // step such that height * step = k * 2^32 + extra for the smallest k that allows it.
        for (std::uint64_t k = 1; k <= 2; ++k) {
          const std::uint64_t total = (k << 32) + extra;
          if (total % height != 0) continue;
          const std::uint64_t step = total / height;
          if (step > 0xffffffffull) continue;
          // A narrow image (within the pixel limit: only the layout is wrong) and the widest the step allows.
          checkOne(header(e, 16, height, std::uint32_t(step), std::size_t(extra)), e);
          checkOne(header(e, std::uint32_t(step / pixel), height, std::uint32_t(step), std::size_t(extra)), e);
        }
      }
      // The wrap reached with the largest step: height * 0xffffffff mod 2^32 = 2^32 - height.
      checkOne(header(e, 16, height, 0xffffffffu, std::size_t((0x100000000ull - height) % 100000)), e);
    }
  }
}

TEST(MessageValidation, AdversarialHeadersForEveryEncoding) {
  for (const EncodingCase& e : kEncodings) {
    SCOPED_TRACE(e.name);
    const std::uint32_t pixel = std::uint32_t(e.channels * e.value_bytes);
    const std::uint32_t w = 40, h = 30, row = w * pixel;
    checkOne(header(e, w, h, row, std::size_t(row) * h), e);                          // exact
    checkOne(header(e, w, h, row + pixel * 3, std::size_t(row + pixel * 3) * h), e);  // padded rows
    checkOne(header(e, w, h, row, std::size_t(row) * h - 1), e);                      // one byte short
    checkOne(header(e, w, h, row, std::size_t(row) * h + 1), e);                      // one byte long
    checkOne(header(e, w, h, row - 1, std::size_t(row - 1) * h), e);                  // step below the row
    checkOne(header(e, w, h, row + 1, std::size_t(row + 1) * h), e);                  // odd step
    checkOne(header(e, w, h, 0, 0), e);                                               // zero step
    checkOne(header(e, 0, h, row, std::size_t(row) * h), e);                          // zero width
    checkOne(header(e, w, 0, row, 0), e);                                             // zero height
    checkOne(header(e, 0, 0, 0, 0), e);                                               // all zero
    checkOne(header(e, 0xffffffffu, 0xffffffffu, 0xffffffffu, 16), e);                // huge, tiny data
    checkOne(header(e, 5000, 5000, 5000 * pixel, 64), e);                             // over the pixel limit
    checkOne(header(e, 0x80000000u, 1, 0x80000000u, 64), e);                          // width beyond int
    auto swapped = header(e, w, h, row, std::size_t(row) * h);
    swapped.is_bigendian = 1;
    checkOne(swapped, e);  // valid: the other byte order is swapped on conversion
    swapped.is_bigendian = 7;
    checkOne(swapped, e);
  }
}

TEST(MessageValidation, RandomHeadersForEveryEncoding) {
  std::mt19937_64 random(20261123);
  auto pick = [&](std::initializer_list<std::uint64_t> choices) {
    return *(choices.begin() + std::uniform_int_distribution<std::size_t>(0, choices.size() - 1)(random));
  };
  int accepted = 0, total = 0;
  for (const EncodingCase& e : kEncodings) {
    SCOPED_TRACE(e.name);
    const std::uint64_t pixel = e.channels * e.value_bytes;
    for (int i = 0; i < 3000; ++i) {
      const std::uint32_t w = std::uint32_t(pick({0, 1, 2, 17, 64, 300, 4097, 65535, 0xffffffffull}) +
                                            std::uniform_int_distribution<int>(0, 3)(random));
      const std::uint32_t h = std::uint32_t(pick({0, 1, 3, 16, 48, 1000, 65536, 0xffffffffull}) +
                                            std::uniform_int_distribution<int>(0, 2)(random));
      const std::uint64_t row = std::uint64_t(w) * pixel;
      const std::uint64_t step64 = pick({row, row + pixel, row + 1, row - 1, row / 2, 0,
                                         std::uniform_int_distribution<std::uint64_t>(0, 0xffffffffull)(random)});
      const std::uint32_t step = std::uint32_t(step64);  // truncated as a 32-bit field would be
      const std::uint64_t exact = std::uint64_t(step) * h;
      std::uint64_t bytes = pick({exact, exact + 1, exact - 1, exact & 0xffffffffull, 0, 8192});
      if (bytes > (1u << 22)) bytes &= 0xfffff;  // never allocate more than a few MB for a header test
      auto m = header(e, w, h, step, std::size_t(bytes));
      m.is_bigendian = std::uint8_t(pick({0, 0, 0, 1, 2}));
      checkOne(m, e);
      if (::testing::Test::HasFatalFailure()) return;
      accepted += exactlyConsistent(m, e) ? 1 : 0;
      ++total;
    }
  }
  // The generator must reach both sides of the rule, or the test proves nothing.
  EXPECT_GT(accepted, total / 50) << accepted << " of " << total;
  EXPECT_LT(accepted, total / 2) << accepted << " of " << total;
}

TEST(MessageValidation, BigEndianDepthIsSwappedNotMisread) {
  for (const EncodingCase& e : {kEncodings[6], kEncodings[7]}) {
    auto m = header(e, 32, 24, std::uint32_t(32 * e.value_bytes), 32 * 24 * e.value_bytes);
    if (e.name == "16UC1") {
      for (std::size_t i = 0; i < m.data.size(); i += 2) {
        m.data[i] = 0x03;
        m.data[i + 1] = 0xE8;
      }  // 1000 mm, big endian
    } else {
      const std::uint8_t one_five[4] = {0x3F, 0xC0, 0x00, 0x00};  // 1.5f, big endian
      for (std::size_t i = 0; i < m.data.size(); i += 4) std::memcpy(&m.data[i], one_five, 4);
    }
    m.is_bigendian = 1;
    const auto input = mc_flow_ros::toFrameInput(partnerOf(m, ImageRole::Depth), m, cameraInfo(32, 24), 1);
    EXPECT_FLOAT_EQ(input.frame.depth(5, 5), e.name == "16UC1" ? 1.0f : 1.5f) << e.name;
  }
}

TEST(MessageValidation, CameraInfoIsCheckedBeforeUse) {
  auto expectRefused = [](const sensor_msgs::CameraInfo& info, InputProblem problem, const std::string& named) {
    try {
      mc_flow_ros::validateCameraInfo(info, kMaxPixels);
      ADD_FAILURE() << "accepted; expected " << named;
    } catch (const FrameInputError& e) {
      EXPECT_EQ(int(e.problem), int(problem)) << e.what();
      EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
    }
  };
  EXPECT_NO_THROW(mc_flow_ros::validateCameraInfo(cameraInfo(640, 480), kMaxPixels));
  EXPECT_NO_THROW(mc_flow_ros::validateCameraInfo(cameraInfo(0, 0), kMaxPixels));  // size unknown: allowed
  auto nan = cameraInfo(640, 480);
  nan.P[2] = std::nan("");
  expectRefused(nan, InputProblem::Intrinsics, "NaN or infinite");
  auto d_inf = cameraInfo(640, 480);
  d_inf.D = {0.1, HUGE_VAL};
  expectRefused(d_inf, InputProblem::Intrinsics, "NaN or infinite");
  expectRefused(cameraInfo(640, 0), InputProblem::Size, "640x0");
  expectRefused(cameraInfo(0xffffffffu, 0xffffffffu), InputProblem::Size, "exceeds the limit");
  auto zero_f = cameraInfo(640, 480);
  zero_f.P[0] = 0;
  expectRefused(zero_f, InputProblem::Intrinsics, "fx=0");
  expectRefused(sensor_msgs::CameraInfo(), InputProblem::Intrinsics, "calibrated");
}
