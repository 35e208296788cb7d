#include "mc_flow/core/soft_labels.h"

#include <algorithm>
#include <cmath>

#include "mc_flow/core/error.h"

namespace mc_flow {

namespace {

void requireSize(const char* what, int width, int height) {
  if (width <= 0 || height <= 0)
    throw InputError(std::string(what) + ": output size " + std::to_string(width) + "x" + std::to_string(height) +
                     " must be positive");
}

void requireLabels(const char* what, const SoftLabels& u) {
  if (u.width <= 0 || u.height <= 0 || u.count <= 0 || u.data.size() != u.planeSize() * std::size_t(u.count))
    throw InputError(std::string(what) + ": soft labels " + std::to_string(u.width) + "x" + std::to_string(u.height) +
                     "x" + std::to_string(u.count) + " are empty or inconsistent with their buffer");
}

}  // namespace

double SoftLabels::support(int i) const {
  if (i < 0 || i >= count) throw InputError("SoftLabels::support: label " + std::to_string(i) + " out of [0, " +
                                            std::to_string(count) + ")");
  const float* p = plane(i);
  const std::size_t n = planeSize();
  double s = 0;
  for (std::size_t k = 0; k < n; ++k) s += p[k];
  return s;
}

void SoftLabels::mergeInto(int i, int into) {
  if (i < 0 || i >= outlier())
    throw InputError("SoftLabels::mergeInto: label " + std::to_string(i) + " is not a motion label (count " +
                     std::to_string(count) + ")");
  if (into < 0 || into >= count || into == i)
    throw InputError("SoftLabels::mergeInto: target label " + std::to_string(into) + " is invalid for merging label " +
                     std::to_string(i) + " (count " + std::to_string(count) + ")");
  const std::size_t n = planeSize();
  const float* src = plane(i);
  float* dst = plane(into);
  for (std::size_t k = 0; k < n; ++k) dst[k] += src[k];
  data.erase(data.begin() + std::ptrdiff_t(std::size_t(i) * n), data.begin() + std::ptrdiff_t(std::size_t(i + 1) * n));
  --count;
}

ImageI32 SoftLabels::argmax() const {
  ImageI32 out(width, height, 1, 0);
  const std::size_t n = planeSize();
  if (count <= 0) return out;
  std::vector<float> best(plane(0), plane(0) + n);
  for (int i = 1; i < count; ++i) {
    const float* p = plane(i);
    for (std::size_t k = 0; k < n; ++k)
      if (p[k] > best[k]) {  // strict: ties keep the lower label index
        best[k] = p[k];
        out.data[k] = i;
      }
  }
  return out;
}

SoftLabels downsampleLabels(const SoftLabels& u, int out_width, int out_height) {
  requireLabels("downsampleLabels", u);
  requireSize("downsampleLabels", out_width, out_height);
  SoftLabels out(out_width, out_height, u.count);
  const int w = u.width, h = u.height;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < out_height; ++y) {
    const int y0 = std::min(2 * y, h - 1), y1 = std::min(2 * y + 1, h - 1);
    for (int i = 0; i < u.count; ++i) {
      const float* src = u.plane(i);
      float* dst = out.plane(i) + std::size_t(y) * out_width;
      const float* r0 = src + std::size_t(y0) * w;
      const float* r1 = src + std::size_t(y1) * w;
      for (int x = 0; x < out_width; ++x) {
        const int x0 = std::min(2 * x, w - 1), x1 = std::min(2 * x + 1, w - 1);
        dst[x] = 0.25f * (r0[x0] + r0[x1] + r1[x0] + r1[x1]);
      }
    }
  }
  return out;
}

SoftLabels upsampleLabels(const SoftLabels& u, int out_width, int out_height) {
  requireLabels("upsampleLabels", u);
  requireSize("upsampleLabels", out_width, out_height);
  SoftLabels out(out_width, out_height, u.count);
  const int w = u.width, h = u.height;

  // Pixel-centre alignment: fine centre x_f maps to coarse coordinate (x_f + 0.5) / s - 0.5, with s the
  // power of two nearest to the size ratio: pyramid levels halve with integer division (an odd last
  // column/row is dropped), so the exact scale between levels is 2^k, not the ratio of the sizes.
  struct Tap {
    int i0, i1;
    float a;
  };
  auto taps = [](int fine, int coarse) {
    std::vector<Tap> t(static_cast<std::size_t>(fine));
    const double ratio = 1.0 / std::exp2(std::round(std::log2(double(fine) / double(coarse))));
    for (int x = 0; x < fine; ++x) {
      const double c = std::clamp((x + 0.5) * ratio - 0.5, 0.0, double(coarse - 1));
      const int i0 = int(c);
      t[std::size_t(x)] = {i0, std::min(i0 + 1, coarse - 1), float(c - i0)};
    }
    return t;
  };
  const std::vector<Tap> tx = taps(out_width, w), ty = taps(out_height, h);

#pragma omp parallel
  {
    std::vector<float> row_sum(static_cast<std::size_t>(out_width));
#pragma omp for schedule(static)
    for (int y = 0; y < out_height; ++y) {
      const Tap& vy = ty[std::size_t(y)];
      std::fill(row_sum.begin(), row_sum.end(), 0.f);
      for (int i = 0; i < u.count; ++i) {
        const float* r0 = u.plane(i) + std::size_t(vy.i0) * w;
        const float* r1 = u.plane(i) + std::size_t(vy.i1) * w;
        float* dst = out.plane(i) + std::size_t(y) * out_width;
        for (int x = 0; x < out_width; ++x) {
          const Tap& vx = tx[std::size_t(x)];
          const float top = r0[vx.i0] + vx.a * (r0[vx.i1] - r0[vx.i0]);
          const float bottom = r1[vx.i0] + vx.a * (r1[vx.i1] - r1[vx.i0]);
          dst[x] = top + vy.a * (bottom - top);
          row_sum[std::size_t(x)] += dst[x];
        }
      }
      // Interpolation keeps the sum at 1 up to rounding; renormalise so downstream steps see an exact simplex.
      // Row-wise (plane by plane) so that memory is read contiguously.
      for (int x = 0; x < out_width; ++x) {
        float& s = row_sum[std::size_t(x)];
        s = s > 0.f ? 1.f / s : 0.f;
      }
      for (int i = 0; i < u.count; ++i) {
        float* dst = out.plane(i) + std::size_t(y) * out_width;
        for (int x = 0; x < out_width; ++x) dst[x] *= row_sum[std::size_t(x)];
      }
      // A pixel without any mass (only possible from an all-zero input) goes to the outlier label.
      float* outlier_row = out.plane(u.count - 1) + std::size_t(y) * out_width;
      for (int x = 0; x < out_width; ++x)
        if (row_sum[std::size_t(x)] == 0.f) outlier_row[x] = 1.f;
    }
  }
  return out;
}

}  // namespace mc_flow
