/**
 * @file soft_labels_pixel.h
 * @brief Resampling soft labels between pyramid levels, per pixel, written once for the CPU (src/core/soft_labels.cpp)
 * and the CUDA kernels (cuda/soft_labels.cu): the 2x2 box average down, the pixel-centre-aligned bilinear taps and
 * interpolation up, and the renormalisation onto the simplex. Every operation is rounded on its own (rounded.h; the
 * taps' double arithmetic too), so both backends resample to the same bits.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/rounded.h"

namespace mc_flow {
namespace soft_labels_pixel {

/// @brief The two source columns (or rows) i0, i1 of target column x when halving a size-`size` axis; an odd last
/// column repeats.
MCFLOW_HOST_DEVICE inline void downsampleSources(int x, int size, int& i0, int& i1) {
  i0 = 2 * x < size - 1 ? 2 * x : size - 1;
  i1 = 2 * x + 1 < size - 1 ? 2 * x + 1 : size - 1;
}

/// @brief The mean of a 2x2 block: 0.25 (((a + b) + c) + d).
MCFLOW_HOST_DEVICE inline float average4(float a, float b, float c, float d) {
  return mulRn(0.25f, addRn(addRn(addRn(a, b), c), d));
}

/// @brief Coarse pixels per fine pixel between two levels: pyramid levels halve with integer division (an odd last
/// column/row is dropped), so the exact scale is the power of two nearest to the size ratio, not the ratio itself.
inline double upsampleRatio(int fine, int coarse) {
  return 1.0 / std::exp2(std::round(std::log2(double(fine) / double(coarse))));
}

/// @brief The bilinear tap of fine column x: coarse neighbours i0, i1 and the weight a of i1. Pixel-centre alignment:
/// fine centre x maps to coarse coordinate (x + 0.5) ratio - 0.5, clamped into [0, coarse - 1]; double products and
/// sums rounded on their own (no FMA on the device).
MCFLOW_HOST_DEVICE inline void upsampleTap(int x, int coarse, double ratio, int& i0, int& i1, float& a) {
#if defined(__CUDA_ARCH__)
  double c = __dadd_rn(__dmul_rn(__dadd_rn(double(x), 0.5), ratio), -0.5);
#else
  double c = (x + 0.5) * ratio - 0.5;
#endif
  const double last = double(coarse - 1);
  c = c < 0.0 ? 0.0 : (last < c ? last : c);
  i0 = int(c);
  i1 = i0 + 1 < coarse - 1 ? i0 + 1 : coarse - 1;
#if defined(__CUDA_ARCH__)
  a = float(__dsub_rn(c, double(i0)));
#else
  a = float(c - i0);
#endif
}

/// @brief Bilinear interpolation of one label from the corners (r0 = upper row, r1 = lower row; x0 left, x1 right).
MCFLOW_HOST_DEVICE inline float interpolate(float r0x0, float r0x1, float r1x0, float r1x1, float ax, float ay) {
  const float top = addRn(r0x0, mulRn(ax, subRn(r0x1, r0x0)));
  const float bottom = addRn(r1x0, mulRn(ax, subRn(r1x1, r1x0)));
  return addRn(top, mulRn(ay, subRn(bottom, top)));
}

/// @brief The factor that renormalises a pixel's interpolated labels (summed in label order) onto the simplex; 0 for
/// a pixel without mass, which then goes to the outlier label.
MCFLOW_HOST_DEVICE inline float renormalisation(float sum) { return sum > 0.f ? divRn(1.f, sum) : 0.f; }

}  // namespace soft_labels_pixel
}  // namespace mc_flow
