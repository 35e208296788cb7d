/**
 * @file image.h
 * @brief Plain row-major image containers, pinhole intrinsics and the RGB-D frame type of the core.
 *
 * Conventions (REP 103 optical frame): x right, y down, z forward; depth in metres along z;
 * 0 or NaN depth = no measurement; intensity in [0, 1].
 */
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace mc_flow {

/// @brief Dense row-major image with `channels` interleaved values per pixel.
template <typename T>
struct Image {
  int width = 0;
  int height = 0;
  int channels = 1;
  std::vector<T> data;

  Image() = default;
  Image(int w, int h, int c = 1, T fill = T()) : width(w), height(h), channels(c), data(std::size_t(w) * h * c, fill) {}

  bool empty() const { return width == 0 || height == 0; }
  std::size_t pixelCount() const { return std::size_t(width) * height; }
  T& operator()(int x, int y, int c = 0) { return data[(std::size_t(y) * width + x) * channels + c]; }
  const T& operator()(int x, int y, int c = 0) const { return data[(std::size_t(y) * width + x) * channels + c]; }
  T* ptr() { return data.data(); }
  const T* ptr() const { return data.data(); }
  bool sameSize(int w, int h) const { return width == w && height == h; }
  template <typename U>
  bool sameSize(const Image<U>& o) const {
    return width == o.width && height == o.height;
  }
};

using ImageF = Image<float>;
using ImageU8 = Image<std::uint8_t>;
using ImageI32 = Image<std::int32_t>;

/// @brief "WxH", or "WxHxC" when channels != 1: how messages name an image size.
inline std::string imageSizeText(int width, int height, int channels = 1) {
  std::string text = std::to_string(width) + "x" + std::to_string(height);
  return channels == 1 ? text : text + "x" + std::to_string(channels);
}
template <typename T>
std::string imageSizeText(const Image<T>& image) {
  return imageSizeText(image.width, image.height, image.channels);
}

/// @brief The one grey conversion of colour input (ITU-R BT.601 luma), in the units of r, g and b.
inline double greyFromRgb(double r, double g, double b) { return 0.299 * r + 0.587 * g + 0.114 * b; }

/// @brief True when a depth value is a usable measurement (finite and > 0).
inline bool isValidDepth(float z) { return std::isfinite(z) && z > 0.f; }

/// @brief Pinhole intrinsics in pixels (principal point in pixel coordinates, pixel centres at integers).
struct Intrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;

  /// @brief Intrinsics of an image scaled by `s` (e.g. 0.5 for one pyramid level down).
  /// Pixel centres are kept consistent: c' = (c + 0.5) * s - 0.5.
  Intrinsics scaled(double s) const { return {fx * s, fy * s, (cx + 0.5) * s - 0.5, (cy + 0.5) * s - 0.5}; }
  /// @brief Throws mc_flow::InputError naming the value when a focal length is not > 0 or any value is not finite.
  void validate() const;
  std::string toString() const;
};

/// @brief One RGB-D frame as the core consumes it.
struct RgbdFrame {
  ImageF intensity;  ///< grey intensity in [0, 1]
  ImageF depth;      ///< metres along the optical axis; 0 or NaN = invalid

  int width() const { return intensity.width; }
  int height() const { return intensity.height; }
  /// @brief Throws mc_flow::InputError when sizes differ, values are not finite, or no depth is valid.
  void validate(const std::string& name) const;
};

}  // namespace mc_flow
