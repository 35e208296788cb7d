#include "mc_flow/core/buffer_layout.h"

#include <limits>

#include "mc_flow/core/error.h"

namespace mc_flow {

bool multiplyWithoutOverflow(std::uint64_t a, std::uint64_t b, std::uint64_t& product) {
  if (a != 0 && b > std::numeric_limits<std::uint64_t>::max() / a) return false;
  product = a * b;
  return true;
}

std::string bufferLayoutProblem(const BufferLayout& layout, std::uint64_t max_pixels) {
  const std::string size = std::to_string(layout.width) + "x" + std::to_string(layout.height);
  if (layout.width == 0 || layout.height == 0) return "empty image (" + size + ")";
  if (layout.channels == 0 || layout.value_bytes == 0) return "no bytes per pixel";
  std::uint64_t pixels = 0;
  if (!multiplyWithoutOverflow(layout.width, layout.height, pixels) || pixels > max_pixels) {
    return "size " + size + " exceeds the limit of " + std::to_string(max_pixels) + " pixels";
  }
  std::uint64_t pixel_bytes = 0, row_bytes = 0;
  if (!multiplyWithoutOverflow(layout.channels, layout.value_bytes, pixel_bytes) ||
      !multiplyWithoutOverflow(layout.width, pixel_bytes, row_bytes)) {
    return "row of " + std::to_string(layout.width) + " px x " + std::to_string(layout.channels) + " x " +
           std::to_string(layout.value_bytes) + " bytes does not fit in 64 bits";
  }
  const std::uint64_t step = layout.row_step;
  if (step < row_bytes) {
    return "step " + std::to_string(step) + " bytes is below the row size " + std::to_string(row_bytes) +
           " bytes (width " + std::to_string(layout.width) + " x " + std::to_string(pixel_bytes) + " bytes per pixel)";
  }
  if (step % layout.value_bytes != 0) {
    return "step " + std::to_string(step) + " bytes is not a multiple of the " + std::to_string(layout.value_bytes) +
           "-byte value size";
  }
  std::uint64_t needed = 0;
  if (!multiplyWithoutOverflow(layout.height, step, needed)) {
    return "height " + std::to_string(layout.height) + " x step " + std::to_string(step) +
           " bytes does not fit in 64 bits";
  }
  if (layout.exact ? needed != layout.available_bytes : needed > layout.available_bytes) {
    return "height " + std::to_string(layout.height) + " x step " + std::to_string(step) + " = " +
           std::to_string(needed) + " bytes, but " + std::to_string(layout.available_bytes) + " bytes of data " +
           (layout.exact ? "are present" : "are left");
  }
  return {};
}

void checkBufferLayout(const BufferLayout& layout, const std::string& what, std::uint64_t max_pixels) {
  const std::string problem = bufferLayoutProblem(layout, max_pixels);
  if (!problem.empty()) throw InputError(what + ": " + problem);
}

}  // namespace mc_flow
