/**
 * @file soft_labels.h
 * @brief Soft label functions u_i(x): one plane per label, the last plane is the outlier label.
 */
#pragma once

#include <cstddef>
#include <vector>

#include "mc_flow/core/image.h"

namespace mc_flow {

/// @brief count planes of width x height floats, label-major (plane i at data[i * width * height]).
/// Plane count-1 is the outlier label; every pixel sums to 1 over the planes.
struct SoftLabels {
  int width = 0, height = 0, count = 0;
  std::vector<float> data;

  SoftLabels() = default;
  SoftLabels(int w, int h, int n, float fill = 0.f)
      : width(w), height(h), count(n), data(std::size_t(w) * h * n, fill) {}
  std::size_t planeSize() const { return std::size_t(width) * height; }
  float* plane(int i) { return data.data() + std::size_t(i) * planeSize(); }
  const float* plane(int i) const { return data.data() + std::size_t(i) * planeSize(); }
  float& at(int i, int x, int y) { return plane(i)[std::size_t(y) * width + x]; }
  float at(int i, int x, int y) const { return plane(i)[std::size_t(y) * width + x]; }
  int outlier() const { return count - 1; }
  int motionLabels() const { return count - 1; }
  /// @brief Sum over all pixels of plane i.
  double support(int i) const;
  /// @brief Removes plane i (not the outlier) after adding it into plane `into`.
  void mergeInto(int i, int into);
  /// @brief Per-pixel argmax over all planes (the outlier plane included).
  ImageI32 argmax() const;
};

/// @brief 2x2 block average (each coarse pixel keeps summing to 1).
SoftLabels downsampleLabels(const SoftLabels& u, int out_width, int out_height);
/// @brief Bilinear upsampling to (w, h) with pixel-centre alignment; renormalised to the simplex.
SoftLabels upsampleLabels(const SoftLabels& u, int out_width, int out_height);

}  // namespace mc_flow
