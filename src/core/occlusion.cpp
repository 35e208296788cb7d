#include "mc_flow/core/occlusion.h"

#include <cmath>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/core/occlusion_pixel.h"

namespace mc_flow {

namespace {

inline bool finitePoint(const float* P) { return std::isfinite(P[0]) && std::isfinite(P[1]) && std::isfinite(P[2]); }

}  // namespace

ImageU8 detectOcclusions(const ImageF& warped_points, const ImageF& depth2, const Intrinsics& K, const Config& config) {
  if (warped_points.channels != 3)
    throw InputError("detectOcclusions: warped points have " + std::to_string(warped_points.channels) +
                     " channels, expected 3");
  if (depth2.channels != 1 || depth2.empty())
    throw InputError("detectOcclusions: depth2 must be a non-empty 1 channel image");
  const int w = warped_points.width, h = warped_points.height;
  const int w2 = depth2.width, h2 = depth2.height;

  // Target pixel of every frame-1 pixel, computed once and reused by the count and the test.
  std::vector<long> target(warped_points.pixelCount(), -1);
  std::vector<int> count(depth2.pixelCount(), 0);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* P = &warped_points(x, y, 0);
      if (!finitePoint(P)) continue;
      const long t = long(occlusion_pixel::targetPixel(P, K.fx, K.fy, K.cx, K.cy, w2, h2));
      target[std::size_t(y) * w + x] = t;
      if (t >= 0) {
#pragma omp atomic
        ++count[std::size_t(t)];
      }
    }

  const float kz = float(config.occlusion_kz), ko = float(config.occlusion_ko);
  ImageU8 mask(w, h, 1, 0);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* P = &warped_points(x, y, 0);
      if (!finitePoint(P)) continue;
      const long t = target[std::size_t(y) * w + x];
      if (t < 0) {  // out of view (or behind the camera) in frame 2
        mask(x, y) = 255;
        continue;
      }
      if (occlusion_pixel::occluded(count[std::size_t(t)], P[2], depth2.data[std::size_t(t)], kz, ko)) mask(x, y) = 255;
    }
  return mask;
}

}  // namespace mc_flow
