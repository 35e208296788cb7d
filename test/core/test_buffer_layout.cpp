// The one layout rule for untrusted headers (messages, files), at the edges of 64-bit arithmetic.
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>

#include "mc_flow/core/buffer_layout.h"
#include "mc_flow/core/error.h"

using mc_flow::BufferLayout;

namespace {

BufferLayout layout(std::uint64_t w, std::uint64_t h, std::uint64_t step, std::uint64_t bytes, bool exact = true) {
  BufferLayout l;
  l.width = w;
  l.height = h;
  l.channels = 1;
  l.value_bytes = 4;
  l.row_step = step;
  l.available_bytes = bytes;
  l.exact = exact;
  return l;
}

constexpr std::uint64_t kMax = std::numeric_limits<std::uint64_t>::max();

}  // namespace

TEST(BufferLayout, ExactAndPaddedLayoutsPass) {
  EXPECT_EQ(mc_flow::bufferLayoutProblem(layout(10, 3, 40, 120)), "");
  EXPECT_EQ(mc_flow::bufferLayoutProblem(layout(10, 3, 48, 144)), "");
  EXPECT_EQ(mc_flow::bufferLayoutProblem(layout(10, 3, 40, 500, false)), "");  // a file with more after it
}

TEST(BufferLayout, ProductsThatWrapAroundTwoToThe64AreRefused) {
  // height * step = 2^64 + 16 wraps to 16 in 64 bits.
  const std::uint64_t step = (std::uint64_t(1) << 62) + 4;  // x 4 = 2^64 + 16
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(1, 4, step, 16), kMax), "");
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(1, 4, step, 16), kMax).find("does not fit in 64 bits"),
            std::string::npos);
  // width * value bytes wraps.
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(std::uint64_t(1) << 62, 1, 0, 0), kMax).find("does not fit"),
            std::string::npos);
  // width * height wraps (over any pixel limit).
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(std::uint64_t(1) << 32, std::uint64_t(1) << 32, 0, 0), kMax)
                .find("exceeds the limit"),
            std::string::npos);
}

TEST(BufferLayout, EachProblemIsNamed) {
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(0, 3, 40, 0)).find("empty image (0x3)"), std::string::npos);
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(10, 3, 0, 120)).find("step 0 bytes is below the row size 40"),
            std::string::npos);
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(10, 3, 36, 108)).find("step 36 bytes is below the row size 40"),
            std::string::npos);
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(10, 3, 42, 126)).find("not a multiple of the 4-byte value size"),
            std::string::npos);
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(10, 3, 40, 121)).find("120 bytes, but 121 bytes"), std::string::npos);
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(10, 3, 40, 119, false)).find("120 bytes, but 119 bytes"),
            std::string::npos);
  EXPECT_NE(mc_flow::bufferLayoutProblem(layout(5000, 5000, 0, 100000000), 1000).find("limit of 1000 pixels"),
            std::string::npos);
  EXPECT_THROW(mc_flow::checkBufferLayout(layout(10, 3, 40, 7), "x.pfm"), mc_flow::InputError);
}
