#include "mc_flow/core/soft_labels.h"

#include <algorithm>
#include <cmath>

#include "mc_flow/core/error.h"
#include "mc_flow/core/soft_labels_pixel.h"

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
  if (i < 0 || i >= count)
    throw InputError("SoftLabels::support: label " + std::to_string(i) + " out of [0, " + std::to_string(count) + ")");
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

namespace {
// The checked input of a resampling of `u` and its output, out_width x out_height with u's labels.
SoftLabels resizedOutput(const char* what, const SoftLabels& u, int out_width, int out_height) {
  requireLabels(what, u);
  requireSize(what, out_width, out_height);
  return SoftLabels(out_width, out_height, u.count);
}
}  // namespace

SoftLabels downsampleLabels(const SoftLabels& u, int out_width, int out_height) {
  SoftLabels out = resizedOutput("downsampleLabels", u, out_width, out_height);
  const int w = u.width, h = u.height;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < out_height; ++y) {
    int y0, y1;
    soft_labels_pixel::downsampleSources(y, h, y0, y1);
    for (int i = 0; i < u.count; ++i) {
      const float* src = u.plane(i);
      float* dst = out.plane(i) + std::size_t(y) * out_width;
      const float* r0 = src + std::size_t(y0) * w;
      const float* r1 = src + std::size_t(y1) * w;
      for (int x = 0; x < out_width; ++x) {
        int x0, x1;
        soft_labels_pixel::downsampleSources(x, w, x0, x1);
        dst[x] = soft_labels_pixel::average4(r0[x0], r0[x1], r1[x0], r1[x1]);
      }
    }
  }
  return out;
}

SoftLabels upsampleLabels(const SoftLabels& u, int out_width, int out_height) {
  SoftLabels out = resizedOutput("upsampleLabels", u, out_width, out_height);
  const int w = u.width, h = u.height;

  // Pixel-centre-aligned taps (soft_labels_pixel::upsampleTap), once per column and per row.
  struct Tap {
    int i0, i1;
    float a;
  };
  auto taps = [](int fine, int coarse) {
    std::vector<Tap> t(static_cast<std::size_t>(fine));
    const double ratio = soft_labels_pixel::upsampleRatio(fine, coarse);
    for (int x = 0; x < fine; ++x) {
      Tap& tap = t[std::size_t(x)];
      soft_labels_pixel::upsampleTap(x, coarse, ratio, tap.i0, tap.i1, tap.a);
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
          dst[x] = soft_labels_pixel::interpolate(r0[vx.i0], r0[vx.i1], r1[vx.i0], r1[vx.i1], vx.a, vy.a);
          row_sum[std::size_t(x)] += dst[x];
        }
      }
      // Interpolation keeps the sum at 1 up to rounding; renormalise so downstream steps see an exact simplex.
      // Row-wise (plane by plane) so that memory is read contiguously.
      for (int x = 0; x < out_width; ++x) {
        float& s = row_sum[std::size_t(x)];
        s = soft_labels_pixel::renormalisation(s);
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
