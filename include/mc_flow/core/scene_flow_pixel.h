/**
 * @file scene_flow_pixel.h
 * @brief The warp of a point by its interpolated motion (eq. 2) and the flows it gives, written once for the CPU
 * (warpPoints and sceneAndOpticalFlow of src/core/scene_flow.cpp) and the CUDA kernels (cuda/scene_flow.cu's
 * outputs, cuda/occlusion.cu's warp).
 *
 * A pixel's motion: the mean twist of the motion labels by its weights u_i, a single label's own transform where
 * only one has mass, the largest label's where (almost) none has. `motions` holds 18 doubles per motion label: the
 * twist, then rows 0..2 of its exp (row-major 3x4; packMotions of scene_flow.h).
 */
#pragma once

#include <cstddef>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/se3_coefficients.h"

namespace mc_flow {
namespace scene_flow_pixel {

/// Below this total motion-label mass the renormalised weights are dominated by noise: the largest label's motion.
constexpr float kMinMotionMass = 1e-3f;
constexpr int kMotionValues = 18;  ///< doubles per motion label in `motions`

/// @brief A pixel's sums over the motion labels, added label by label in ascending order.
struct MotionSums {
  double mass = 0.0;
  double xi[6] = {0, 0, 0, 0, 0, 0};
  int nonzero = 0;  ///< labels with u != 0
  int last = 0;     ///< the last of them
};

/// @brief Adds motion label i with weight u (labels in ascending order; zero weights are skipped).
MCFLOW_HOST_DEVICE inline void addMotionLabel(MotionSums& s, int i, double u, const double* twist) {
  if (u == 0.0) return;
  s.mass += u;
  for (int c = 0; c < 6; ++c) s.xi[c] += u * twist[c];
  ++s.nonzero;
  s.last = i;
}

/// @brief The motion label with the largest u at pixel `idx` (the lowest index on ties); `u` holds a plane of `plane`
/// values per label.
MCFLOW_HOST_DEVICE inline int largestMotionLabel(const float* u, std::size_t plane, std::size_t idx,
                                                 int motion_labels) {
  int label = 0;
  for (int i = 1; i < motion_labels; ++i)
    if (u[i * plane + idx] > u[label * plane + idx]) label = i;
  return label;
}

/// @brief Q = the point P moved by the pixel's motion, in double. `largest_label()` gives the motion label with the
/// largest u (the lowest index on ties); it is asked only where the mass is below kMinMotionMass.
template <typename LargestLabel>
MCFLOW_HOST_DEVICE void warpPoint(const float P[3], MotionSums& s, const double* motions,
                                  const LargestLabel& largest_label, double Q[3]) {
  double T[12];
  const double* transform = T;
  if (s.mass < double(kMinMotionMass)) {
    transform = motions + kMotionValues * largest_label() + 6;
  } else if (s.nonzero == 1) {
    transform = motions + kMotionValues * s.last + 6;
  } else {
    for (int c = 0; c < 6; ++c) s.xi[c] /= s.mass;
    se3ExpRows(s.xi, T);
  }
  for (int r = 0; r < 3; ++r)
    Q[r] = transform[4 * r] * double(P[0]) + transform[4 * r + 1] * double(P[1]) + transform[4 * r + 2] * double(P[2]) +
           transform[4 * r + 3];
}

/// @brief Optical flow of pixel (x, y) whose point moved to Q (finite): false when Q is not in front of the camera
/// (a point moved behind it has no image position).
MCFLOW_HOST_DEVICE inline bool opticalFlow(const float Q[3], double fx, double fy, double cx, double cy, int x, int y,
                                           float flow[2]) {
  if (!(Q[2] > 0.f)) return false;
  flow[0] = float(fx * Q[0] / Q[2] + cx - x);
  flow[1] = float(fy * Q[1] / Q[2] + cy - y);
  return true;
}

}  // namespace scene_flow_pixel
}  // namespace mc_flow
