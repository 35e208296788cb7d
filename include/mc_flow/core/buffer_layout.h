/**
 * @file buffer_layout.h
 * @brief Checks the layout an untrusted header declares for a row-major pixel buffer (an image message,
 * an image or flow file) against the bytes that are really there, in 64-bit arithmetic that cannot wrap.
 *
 * One rule for every reader: the ROS message validation (src/ros/message_validation.cpp) and the file
 * loaders (src/io) call it before any library touches the buffer, so no header can make a reader run past
 * the data (e.g. `height * step` wrapping around 2^32 onto the data size).
 */
#pragma once

#include <cstdint>
#include <string>

namespace mc_flow {

/// @brief Default upper bound on the pixels of one input image (16384 x 16384).
constexpr std::uint64_t kDefaultMaxInputPixels = 16384ull * 16384ull;

/// @brief A buffer layout as declared by a header. All sizes are as read, before any check.
struct BufferLayout {
  std::uint64_t width = 0;            ///< [px]
  std::uint64_t height = 0;           ///< [px]
  std::uint64_t channels = 1;         ///< values per pixel
  std::uint64_t value_bytes = 1;      ///< bytes per value (1, 2, 4)
  std::uint64_t row_step = 0;         ///< [bytes] from one row to the next
  std::uint64_t available_bytes = 0;  ///< bytes really present for the pixels
  /// true: the data must be exactly height * row_step bytes (a message); false: at least that (a file
  /// whose payload may be followed by other bytes).
  bool exact = true;
};

/// @brief Product of two sizes, or false when it does not fit in 64 bits.
bool multiplyWithoutOverflow(std::uint64_t a, std::uint64_t b, std::uint64_t& product);

/// @brief Empty when `layout` is consistent, else a sentence naming each offending value (for an error
/// message prefixed by what was read). Checks: width, height > 0; width * height <= max_pixels;
/// row_step >= width * channels * value_bytes; row_step a multiple of value_bytes; height * row_step
/// against available_bytes (equal when exact, at most otherwise); no product overflows.
std::string bufferLayoutProblem(const BufferLayout& layout, std::uint64_t max_pixels = kDefaultMaxInputPixels);

/// @brief Throws InputError("<what>: <problem>") when bufferLayoutProblem() finds one.
void checkBufferLayout(const BufferLayout& layout, const std::string& what,
                       std::uint64_t max_pixels = kDefaultMaxInputPixels);

}  // namespace mc_flow
