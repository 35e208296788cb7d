// Small analytic scenes for unit tests of the motion and label stages (independent of the synthetic
// scene generator, so a bug there cannot hide a bug here).
#pragma once

#include <cmath>

#include "mc_flow/core/image.h"
#include "mc_flow/core/se3.h"

namespace mc_flow {
namespace test {

/// Smooth texture defined on 3D points, so brightness constancy holds exactly under any motion.
inline float textureAt(const Eigen::Vector3d& P) {
  const double v = 0.5 + 0.18 * std::sin(9.0 * P.x() + 2.0 * P.z()) + 0.14 * std::sin(11.0 * P.y() - 3.0 * P.x()) +
                   0.08 * std::sin(23.0 * P.x() + 19.0 * P.y() + 5.0 * P.z());
  return float(std::min(1.0, std::max(0.0, v)));
}

/// Scene of two planes (a slanted back wall and a floor) seen by a camera; frame 2 sees the scene moved
/// by T (points of frame 1 map to T * P in frame 2). Rendered by exact ray casting.
struct TwoPlaneScene {
  Intrinsics K;
  RgbdFrame frame1, frame2;
};

inline TwoPlaneScene renderTwoPlaneScene(int width, int height, const Eigen::Matrix4d& T) {
  TwoPlaneScene s;
  const double f = 263.7 * width / 320.0;
  s.K = {f, f, (width - 1) / 2.0, (height - 1) / 2.0};
  // Planes n . P = d in frame-1 coordinates.
  const Eigen::Vector3d n_wall = Eigen::Vector3d(0.15, -0.1, -1.0).normalized();
  const double d_wall = n_wall.dot(Eigen::Vector3d(0, 0, 3.0));
  const Eigen::Vector3d n_floor = Eigen::Vector3d(0.05, -1.0, -0.25).normalized();
  const double d_floor = n_floor.dot(Eigen::Vector3d(0, 0.6, 2.0));
  const Eigen::Matrix4d Tinv = T.inverse();
  auto render = [&](const Eigen::Matrix4d& pose, RgbdFrame& frame) {
    // pose maps frame-1 coordinates to this frame's camera coordinates.
    const Eigen::Matrix4d back = pose.inverse();
    frame.intensity = ImageF(width, height, 1, 0.f);
    frame.depth = ImageF(width, height, 1, 0.f);
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) {
        const Eigen::Vector3d ray((x - s.K.cx) / s.K.fx, (y - s.K.cy) / s.K.fy, 1.0);
        // Ray in frame-1 coordinates: origin o + t * dir.
        const Eigen::Vector3d o = back.topRightCorner<3, 1>();
        const Eigen::Vector3d dir = back.topLeftCorner<3, 3>() * ray;
        double best = 1e9;
        for (int p = 0; p < 2; ++p) {
          const Eigen::Vector3d& n = p == 0 ? n_wall : n_floor;
          const double d = p == 0 ? d_wall : d_floor;
          const double denom = n.dot(dir);
          if (std::fabs(denom) < 1e-9) continue;
          const double t = (d - n.dot(o)) / denom;
          if (t > 0.1 && t < best) best = t;
        }
        if (best > 100) continue;
        const Eigen::Vector3d P1 = o + best * dir;  // frame-1 coordinates
        frame.intensity(x, y) = textureAt(P1);
        frame.depth(x, y) = float(best);  // ray has z = 1 in camera coordinates: t is the depth
      }
  };
  render(Eigen::Matrix4d::Identity(), s.frame1);
  render(T, s.frame2);
  (void)Tinv;
  return s;
}

/// A fronto-parallel textured wall at 2.5 m whose left half (X < split_x in frame-1 coordinates) moves by T
/// while the right half stays: a motion boundary that no depth cue reveals, so K-means clusters straddle
/// it and only the label step can put the boundary in the right place. Also returns the true flow.
struct SplitPlaneScene {
  Intrinsics K;
  RgbdFrame frame1, frame2;
  ImageF gt_optical_flow;  // 2 channels
};

inline SplitPlaneScene renderSplitPlaneScene(int width, int height, const Eigen::Matrix4d& T, double split_x) {
  SplitPlaneScene s;
  const double f = 263.7 * width / 320.0;
  s.K = {f, f, (width - 1) / 2.0, (height - 1) / 2.0};
  const double wall = 2.5;
  const Eigen::Matrix4d Tinv = T.inverse();
  s.frame1.intensity = ImageF(width, height, 1, 0.f);
  s.frame1.depth = ImageF(width, height, 1, 0.f);
  s.frame2 = s.frame1;
  s.gt_optical_flow = ImageF(width, height, 2, 0.f);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const Eigen::Vector3d ray((x - s.K.cx) / s.K.fx, (y - s.K.cy) / s.K.fy, 1.0);
      // frame 1
      const Eigen::Vector3d P = wall * ray;
      s.frame1.intensity(x, y) = textureAt(P);
      s.frame1.depth(x, y) = float(wall);
      const Eigen::Vector3d P2 = P.x() < split_x ? Eigen::Vector3d((T * P.homogeneous()).head<3>()) : P;
      s.gt_optical_flow(x, y, 0) = float(s.K.fx * P2.x() / P2.z() + s.K.cx - x);
      s.gt_optical_flow(x, y, 1) = float(s.K.fy * P2.y() / P2.z() + s.K.cy - y);
      // frame 2: the static half, or the moved half (ray taken back into frame-1 coordinates)
      double best = 1e9;
      Eigen::Vector3d hit_frame1;
      if (P.x() >= split_x) {
        best = wall;
        hit_frame1 = P;
      }
      const Eigen::Vector3d o = Tinv.topRightCorner<3, 1>(), dir = Tinv.topLeftCorner<3, 3>() * ray;
      const double t = (wall - o.z()) / dir.z();
      const Eigen::Vector3d Q = o + t * dir;
      if (t > 0.1 && Q.x() < split_x && t < best) {
        best = t;
        hit_frame1 = Q;
      }
      if (best > 100) continue;
      s.frame2.intensity(x, y) = textureAt(hit_frame1);
      s.frame2.depth(x, y) = float(best);
    }
  return s;
}

}  // namespace test
}  // namespace mc_flow
