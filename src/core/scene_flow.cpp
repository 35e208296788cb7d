#include "mc_flow/core/scene_flow.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mc_flow/core/error.h"

namespace mc_flow {

namespace {

// Below this total motion-label mass the renormalised weights are dominated by noise.
constexpr float kMinMotionMass = 1e-3f;

void requireTwistCount(const char* what, const SoftLabels& u, const std::vector<Vector6d>& twists) {
  if (u.count < 1 || int(twists.size()) != u.count - 1)
    throw InputError(std::string(what) + ": " + std::to_string(twists.size()) + " twists for " +
                     std::to_string(u.count) + " label planes (expected one twist per motion label, count - 1)");
}

/// The motion label a pixel without (enough) motion-label mass takes: the one with the largest value (the lowest
/// index on ties).
int largestMotionLabel(const SoftLabels& u, std::size_t k) {
  int label = 0;
  for (int i = 1; i < u.count - 1; ++i)
    if (u.plane(i)[k] > u.plane(label)[k]) label = i;
  return label;
}

}  // namespace

ImageF warpPoints(const ImageF& points, const SoftLabels& u, const std::vector<Vector6d>& twists) {
  requireTwistCount("warpPoints", u, twists);
  if (points.channels != 3 || !points.sameSize(u.width, u.height))
    throw InputError("warpPoints: points " + std::to_string(points.width) + "x" + std::to_string(points.height) + "x" +
                     std::to_string(points.channels) + " do not match labels " + std::to_string(u.width) + "x" +
                     std::to_string(u.height) + " (3 channels expected)");
  const int w = points.width, h = points.height, m = u.count - 1;
  const float nan = std::numeric_limits<float>::quiet_NaN();

  // Pixels owned by a single label (the common case) reuse that label's transform.
  std::vector<Eigen::Matrix4d> label_transform(static_cast<std::size_t>(m));
  for (int i = 0; i < m; ++i) label_transform[std::size_t(i)] = se3Exp(twists[std::size_t(i)]);

  ImageF warped(w, h, 3);
#pragma omp parallel
  {
    // Row accumulators: the label planes are read row by row (contiguous) instead of across planes per pixel.
    std::vector<double> mass(static_cast<std::size_t>(w)), xi_sum(std::size_t(6) * w);
    std::vector<int> nonzero(static_cast<std::size_t>(w)), last_label(static_cast<std::size_t>(w));
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y) {
      std::fill(mass.begin(), mass.end(), 0.0);
      std::fill(xi_sum.begin(), xi_sum.end(), 0.0);
      std::fill(nonzero.begin(), nonzero.end(), 0);
      for (int i = 0; i < m; ++i) {
        const float* row = u.plane(i) + std::size_t(y) * w;
        const Vector6d& tw = twists[std::size_t(i)];
        for (int x = 0; x < w; ++x) {
          const double v = row[x];
          if (v == 0.0) continue;
          mass[std::size_t(x)] += v;
          double* acc = &xi_sum[std::size_t(6) * x];
          for (int c = 0; c < 6; ++c) acc[c] += v * tw[c];
          ++nonzero[std::size_t(x)];
          last_label[std::size_t(x)] = i;
        }
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
        const std::size_t xs = std::size_t(x);
        Eigen::Matrix4d T;
        if (mass[xs] < kMinMotionMass) {
          T = label_transform[std::size_t(largestMotionLabel(u, std::size_t(y) * w + x))];
        } else if (nonzero[xs] == 1) {
          T = label_transform[std::size_t(last_label[xs])];
        } else {
          const Vector6d xi = Eigen::Map<const Vector6d>(&xi_sum[6 * xs]) / mass[xs];
          T = se3Exp(xi);
        }
        const Eigen::Vector3d p(P[0], P[1], P[2]);
        const Eigen::Vector3d q = T.topLeftCorner<3, 3>() * p + T.topRightCorner<3, 1>();
        Q[0] = float(q.x()), Q[1] = float(q.y()), Q[2] = float(q.z());
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
      if (Q[2] > 0.f) {  // a point moved behind the camera has no image position
        o[0] = float(K.fx * Q[0] / Q[2] + K.cx - x);
        o[1] = float(K.fy * Q[1] / Q[2] + K.cy - y);
      } else {
        o[0] = o[1] = nan;
      }
    }
}

}  // namespace mc_flow
