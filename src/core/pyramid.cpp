#include "mc_flow/core/pyramid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mc_flow/core/error.h"
#include "mc_flow/core/pyramid_pixel.h"

namespace mc_flow {

namespace {

// Every pyramid step halves with integer division: output pixel i covers input pixels 2i and 2i+1, so its
// centre sits at input coordinate 2i + 0.5, which is exactly what Intrinsics::scaled(0.5) assumes.
int halved(int n) { return std::max(1, n / 2); }

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

int pyramidLevelExtent(int n, int level) {
  for (int l = 0; l < level; ++l) n = halved(n);
  return n;
}

ImageF downsampleIntensity(const ImageF& image) {
  if (image.empty()) throw InputError("downsampleIntensity: empty image");
  const int w = image.width, h = image.height, ow = halved(w), oh = halved(h), c = image.channels;
  ImageF horizontal(ow, h, c);
  ImageF out(ow, oh, c);
  // The two passes of pyramid_pixel::downsampledIntensity, each pixel once.
#pragma omp parallel
  {
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y)
      for (int ch = 0; ch < c; ++ch) {
        const auto at = [&](int xi, int yi) { return image(xi, yi, ch); };
        for (int x = 0; x < ow; ++x) horizontal(x, y, ch) = pyramid_pixel::downsampleRow(at, w, x, y);
      }
#pragma omp for schedule(static)
    for (int y = 0; y < oh; ++y)
      for (int x = 0; x < ow; ++x)
        for (int ch = 0; ch < c; ++ch) {
          const auto at = [&](int xi, int yi) { return horizontal(xi, yi, ch); };
          out(x, y, ch) = pyramid_pixel::filter1331(at(x, pyramid_pixel::clampIndex(2 * y - 1, h)),
                                                    at(x, pyramid_pixel::clampIndex(2 * y, h)),
                                                    at(x, pyramid_pixel::clampIndex(2 * y + 1, h)),
                                                    at(x, pyramid_pixel::clampIndex(2 * y + 2, h)));
        }
  }
  return out;
}

ImageF downsampleDepth(const ImageF& depth, double range) {
  if (depth.empty()) throw InputError("downsampleDepth: empty image");
  if (depth.channels != 1) throw InputError("downsampleDepth: " + std::to_string(depth.channels) + " channels, expected 1");
  const int w = depth.width, h = depth.height, ow = halved(w), oh = halved(h);
  const float max_diff = float(range);
  const auto at = [&](int x, int y) { return depth(x, y); };
  ImageF out(ow, oh, 1, 0.f);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < oh; ++y)
    for (int x = 0; x < ow; ++x) out(x, y) = pyramid_pixel::downsampledDepth(at, w, h, x, y, max_diff);
  return out;
}

ImageF backProject(const ImageF& depth, const Intrinsics& K) {
  if (depth.channels != 1) throw InputError("backProject: depth has " + std::to_string(depth.channels) + " channels");
  const int w = depth.width, h = depth.height;
  ImageF points(w, h, 3);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double inv_fx = 1.0 / K.fx, inv_fy = 1.0 / K.fy;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float z = depth(x, y);
      float* p = &points(x, y, 0);
      if (isValidDepth(z))
        pyramid_pixel::backProjectPixel(z, x, y, K.cx, K.cy, inv_fx, inv_fy, p);
      else
        p[0] = p[1] = p[2] = nan;
    }
  return points;
}

ImageF blendedGradient(const ImageF& f, const ImageF* validity_source, float eps) {
  if (f.channels != 1) throw InputError("blendedGradient: image has " + std::to_string(f.channels) + " channels, expected 1");
  if (validity_source && !validity_source->sameSize(f))
    throw InputError("blendedGradient: validity source size differs from the image");
  const int w = f.width, h = f.height;
  ImageF grad(w, h, 2, 0.f);
  const auto at = [&](int x, int y) { return f(x, y); };
  const auto usable = [&](int x, int y) { return !validity_source || isValidDepth((*validity_source)(x, y)); };
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) pyramid_pixel::blendedGradientAt(at, usable, w, h, x, y, eps, &grad(x, y, 0));
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
  for (long i = 0; i < n; ++i) z[i] = pyramid_pixel::cleanDepth(z[i], min_depth, max_depth);

  for (int l = 0; l < levels; ++l) {
    PyramidLevel& level = pyramid.levels[std::size_t(l)];
    if (l > 0) {
      const PyramidLevel& finer = pyramid.levels[std::size_t(l - 1)];
      level.intensity = downsampleIntensity(finer.intensity);
      level.depth = downsampleDepth(finer.depth, config.depth_downsample_range);
    }
    level.intrinsics = K.scaled(std::ldexp(1.0, -l));
    level.points = backProject(level.depth, level.intrinsics);
    level.intensity_grad = blendedGradient(level.intensity, nullptr, pyramid_pixel::kIntensityGradientEps);
    level.depth_grad = blendedGradient(level.depth, &level.depth, pyramid_pixel::kDepthGradientEps);
  }
  return pyramid;
}

}  // namespace mc_flow
