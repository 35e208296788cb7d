#include "mc_flow/core/pyramid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mc_flow/core/error.h"

namespace mc_flow {

namespace {

// Every pyramid step halves with integer division: output pixel i covers input pixels 2i and 2i+1, so its
// centre sits at input coordinate 2i + 0.5, which is exactly what Intrinsics::scaled(0.5) assumes.
int halved(int n) { return std::max(1, n / 2); }

constexpr float kIntensityGradientEps = 1e-6f;  // docs/ALGORITHM.md, 'Gradients' (the PD-Flow blend)
constexpr float kDepthGradientEps = 0.005f;     // [m]

// One-dimensional blended derivative at a pixel from its backward (f0 - fm) and forward (fp - f0) differences.
inline float blend(float backward, float forward, float eps) {
  const float r_back = std::fabs(backward) + eps, r_fwd = std::fabs(forward) + eps;
  // Each difference is weighted by the other's magnitude, so the smaller difference dominates.
  return (r_back * forward + r_fwd * backward) / (r_back + r_fwd);
}

}  // namespace

int PyramidLevel::validCount() const {
  int n = 0;
  for (const float z : depth.data) n += z > 0.f ? 1 : 0;
  return n;
}

int pyramidLevelCount(int width, int height, int coarsest_min_width) {
  const int min_width = std::max(1, coarsest_min_width);
  int levels = 1;
  while (width / 2 >= min_width && height / 2 >= 1) {
    width /= 2;
    height /= 2;
    ++levels;
  }
  return levels;
}

ImageF downsampleIntensity(const ImageF& image) {
  if (image.empty()) throw InputError("downsampleIntensity: empty image");
  const int w = image.width, h = image.height, ow = halved(w), oh = halved(h), c = image.channels;
  const float k[4] = {1.f / 8, 3.f / 8, 3.f / 8, 1.f / 8};
  ImageF horizontal(ow, h, c);
  ImageF out(ow, oh, c);
#pragma omp parallel
  {
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < ow; ++x)
        for (int ch = 0; ch < c; ++ch) {
          float s = 0;
          for (int t = 0; t < 4; ++t) s += k[t] * image(std::clamp(2 * x - 1 + t, 0, w - 1), y, ch);
          horizontal(x, y, ch) = s;
        }
#pragma omp for schedule(static)
    for (int y = 0; y < oh; ++y)
      for (int x = 0; x < ow; ++x)
        for (int ch = 0; ch < c; ++ch) {
          float s = 0;
          for (int t = 0; t < 4; ++t) s += k[t] * horizontal(x, std::clamp(2 * y - 1 + t, 0, h - 1), ch);
          out(x, y, ch) = s;
        }
  }
  return out;
}

ImageF downsampleDepth(const ImageF& depth, double range) {
  if (depth.empty()) throw InputError("downsampleDepth: empty image");
  if (depth.channels != 1) throw InputError("downsampleDepth: " + std::to_string(depth.channels) + " channels, expected 1");
  const int w = depth.width, h = depth.height, ow = halved(w), oh = halved(h);
  const float k[4] = {1.f, 3.f, 3.f, 1.f};
  const float max_diff = float(range);
  ImageF out(ow, oh, 1, 0.f);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < oh; ++y) {
    for (int x = 0; x < ow; ++x) {
      // Reference depth: the lower median of the valid values of the central 2x2 block. An actual sample
      // (never the mean of two) so that a block straddling an edge picks one side instead of a phantom depth.
      float centre[4];
      int n = 0;
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const int xi = std::min(2 * x + dx, w - 1), yi = std::min(2 * y + dy, h - 1);
          const float z = depth(xi, yi);
          if (isValidDepth(z)) centre[n++] = z;
        }
      if (n == 0) continue;
      std::sort(centre, centre + n);
      const float reference = centre[(n - 1) / 2];

      float sum_w = 0, sum_z = 0;
      for (int t = 0; t < 4; ++t) {
        const int yi = 2 * y - 1 + t;
        if (yi < 0 || yi >= h) continue;
        for (int s = 0; s < 4; ++s) {
          const int xi = 2 * x - 1 + s;
          if (xi < 0 || xi >= w) continue;
          const float z = depth(xi, yi);
          if (!isValidDepth(z) || std::fabs(z - reference) > max_diff) continue;
          const float weight = k[t] * k[s];
          sum_w += weight;
          sum_z += weight * z;
        }
      }
      // The reference itself always passes, so sum_w > 0 here.
      out(x, y) = sum_z / sum_w;
    }
  }
  return out;
}

ImageF backProject(const ImageF& depth, const Intrinsics& K) {
  if (depth.channels != 1) throw InputError("backProject: depth has " + std::to_string(depth.channels) + " channels");
  const int w = depth.width, h = depth.height;
  ImageF points(w, h, 3);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double inv_fx = 1.0 / K.fx, inv_fy = 1.0 / K.fy;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y) {
    const float ry = float((y - K.cy) * inv_fy);
    for (int x = 0; x < w; ++x) {
      const float z = depth(x, y);
      float* p = &points(x, y, 0);
      if (!isValidDepth(z)) {
        p[0] = p[1] = p[2] = nan;
        continue;
      }
      p[0] = z * float((x - K.cx) * inv_fx);
      p[1] = z * ry;
      p[2] = z;
    }
  }
  return points;
}

ImageF blendedGradient(const ImageF& f, const ImageF* validity_source, float eps) {
  if (f.channels != 1) throw InputError("blendedGradient: image has " + std::to_string(f.channels) + " channels, expected 1");
  if (validity_source && !validity_source->sameSize(f))
    throw InputError("blendedGradient: validity source size differs from the image");
  const int w = f.width, h = f.height;
  ImageF grad(w, h, 2, 0.f);
  auto valid = [&](int x, int y) { return !validity_source || isValidDepth((*validity_source)(x, y)); };
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      if (!valid(x, y)) continue;
      const float f0 = f(x, y);
      // Along each axis: blend both one-sided differences when both neighbours are usable, else the one left.
      for (int axis = 0; axis < 2; ++axis) {
        const int xm = axis == 0 ? x - 1 : x, ym = axis == 0 ? y : y - 1;
        const int xp = axis == 0 ? x + 1 : x, yp = axis == 0 ? y : y + 1;
        const bool has_m = xm >= 0 && ym >= 0 && valid(xm, ym);
        const bool has_p = xp < w && yp < h && valid(xp, yp);
        float d = 0.f;
        if (has_m && has_p)
          d = blend(f0 - f(xm, ym), f(xp, yp) - f0, eps);
        else if (has_m)
          d = f0 - f(xm, ym);
        else if (has_p)
          d = f(xp, yp) - f0;
        grad(x, y, axis) = d;
      }
    }
  }
  return grad;
}

Pyramid buildPyramid(const RgbdFrame& frame, const Intrinsics& K, int levels, const Config& config) {
  if (levels < 1) throw InputError("buildPyramid: levels = " + std::to_string(levels) + " must be >= 1");
  if (frame.intensity.empty() || !frame.depth.sameSize(frame.intensity))
    throw InputError("buildPyramid: intensity " + std::to_string(frame.intensity.width) + "x" +
                     std::to_string(frame.intensity.height) + " and depth " + std::to_string(frame.depth.width) + "x" +
                     std::to_string(frame.depth.height) + " must be non-empty and of the same size");

  Pyramid pyramid;
  pyramid.levels.resize(std::size_t(levels));

  PyramidLevel& base = pyramid.levels[0];
  base.intensity = frame.intensity;
  base.depth = frame.depth;
  const float min_depth = float(config.min_depth), max_depth = float(config.max_depth);
  float* z = base.depth.ptr();
  const long n = long(base.depth.data.size());
#pragma omp parallel for schedule(static)
  for (long i = 0; i < n; ++i)
    if (!(std::isfinite(z[i]) && z[i] >= min_depth && z[i] <= max_depth)) z[i] = 0.f;

  for (int l = 0; l < levels; ++l) {
    PyramidLevel& level = pyramid.levels[std::size_t(l)];
    if (l > 0) {
      const PyramidLevel& finer = pyramid.levels[std::size_t(l - 1)];
      level.intensity = downsampleIntensity(finer.intensity);
      level.depth = downsampleDepth(finer.depth, config.depth_downsample_range);
    }
    level.intrinsics = K.scaled(std::ldexp(1.0, -l));
    level.points = backProject(level.depth, level.intrinsics);
    level.intensity_grad = blendedGradient(level.intensity, nullptr, kIntensityGradientEps);
    level.depth_grad = blendedGradient(level.depth, &level.depth, kDepthGradientEps);
  }
  return pyramid;
}

}  // namespace mc_flow
