#include "mc_flow/core/scene_flow.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mc_flow/core/error.h"
#include "mc_flow/core/scene_flow_pixel.h"

namespace mc_flow {

namespace {

void requireTwistCount(const char* what, const SoftLabels& u, const std::vector<Vector6d>& twists) {
  if (u.count < 1 || int(twists.size()) != u.count - 1)
    throw InputError(std::string(what) + ": " + std::to_string(twists.size()) + " twists for " +
                     std::to_string(u.count) + " label planes (expected one twist per motion label, count - 1)");
}

}  // namespace

void packMotions(const std::vector<Vector6d>& twists, double* out) {
  for (std::size_t i = 0; i < twists.size(); ++i) {
    const Eigen::Matrix4d T = se3Exp(twists[i]);
    double* motion = out + std::size_t(scene_flow_pixel::kMotionValues) * i;
    for (int k = 0; k < 6; ++k) motion[k] = twists[i](k);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) motion[6 + r * 4 + c] = T(r, c);
  }
}

ImageF warpPoints(const ImageF& points, const SoftLabels& u, const std::vector<Vector6d>& twists) {
  requireTwistCount("warpPoints", u, twists);
  if (points.channels != 3 || !points.sameSize(u.width, u.height))
    throw InputError("warpPoints: points " + std::to_string(points.width) + "x" + std::to_string(points.height) + "x" +
                     std::to_string(points.channels) + " do not match labels " + std::to_string(u.width) + "x" +
                     std::to_string(u.height) + " (3 channels expected)");
  const int w = points.width, h = points.height, m = u.count - 1;
  const float nan = std::numeric_limits<float>::quiet_NaN();

  // Pixels owned by a single label (the common case) reuse that label's transform.
  std::vector<double> motions(std::size_t(scene_flow_pixel::kMotionValues) * std::size_t(m));
  packMotions(twists, motions.data());

  ImageF warped(w, h, 3);
#pragma omp parallel
  {
    // Row accumulators: the label planes are read row by row (contiguous) instead of across planes per pixel.
    std::vector<scene_flow_pixel::MotionSums> sums(static_cast<std::size_t>(w));
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y) {
      std::fill(sums.begin(), sums.end(), scene_flow_pixel::MotionSums{});
      for (int i = 0; i < m; ++i) {
        const float* row = u.plane(i) + std::size_t(y) * w;
        const double* twist = twists[std::size_t(i)].data();
        for (int x = 0; x < w; ++x) scene_flow_pixel::addMotionLabel(sums[std::size_t(x)], i, row[x], twist);
      }
      for (int x = 0; x < w; ++x) {
        const float* P = &points(x, y, 0);
        float* Q = &warped(x, y, 0);
        if (!(std::isfinite(P[0]) && std::isfinite(P[1]) && std::isfinite(P[2]))) {
          Q[0] = Q[1] = Q[2] = nan;
          continue;
        }
        if (m == 0) {
          Q[0] = P[0], Q[1] = P[1], Q[2] = P[2];
          continue;
        }
        const std::size_t k = std::size_t(y) * w + x;
        auto largest = [&u, k]() {
          return scene_flow_pixel::largestMotionLabel(u.data.data(), u.planeSize(), k, u.count - 1);
        };
        double q[3];
        scene_flow_pixel::warpPoint(P, sums[std::size_t(x)], motions.data(), largest, q);
        Q[0] = float(q[0]), Q[1] = float(q[1]), Q[2] = float(q[2]);
      }
    }
  }
  return warped;
}

void sceneAndOpticalFlow(const ImageF& points, const ImageF& warped_points, const Intrinsics& K, ImageF& scene_flow,
                         ImageF& optical_flow) {
  if (points.channels != 3 || warped_points.channels != 3 || !points.sameSize(warped_points))
    throw InputError("sceneAndOpticalFlow: points and warped points must be 3 channel images of the same size");
  const int w = points.width, h = points.height;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  scene_flow = ImageF(w, h, 3);
  optical_flow = ImageF(w, h, 2);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* P = &points(x, y, 0);
      const float* Q = &warped_points(x, y, 0);
      float* s = &scene_flow(x, y, 0);
      float* o = &optical_flow(x, y, 0);
      const bool valid = std::isfinite(P[0]) && std::isfinite(P[1]) && std::isfinite(P[2]) && std::isfinite(Q[0]) &&
                         std::isfinite(Q[1]) && std::isfinite(Q[2]);
      if (!valid) {
        s[0] = s[1] = s[2] = nan;
        o[0] = o[1] = nan;
        continue;
      }
      s[0] = Q[0] - P[0], s[1] = Q[1] - P[1], s[2] = Q[2] - P[2];
      if (!scene_flow_pixel::opticalFlow(Q, K.fx, K.fy, K.cx, K.cy, x, y, o)) o[0] = o[1] = nan;
    }
}

}  // namespace mc_flow
