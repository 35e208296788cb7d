/**
 * @file motion_step_control.h
 * @brief The motion step's per-label step control (Levenberg-Marquardt with backtracking and a trust region),
 * shared by the host IRLS loop (src/core/motion_estimation.cpp) and the device-resident one
 * (cuda/motion_estimation.cu): one definition of when a step is taken, undone or too small.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"

namespace mc_flow {

// A step is undone only when it raised its label's cost by more than this fraction: rounding and the
// first-order twist update make tiny rises near the optimum that are not divergence.
constexpr double kMotionRejectRelativeIncrease = 0.01;
constexpr double kMotionMaxStepTranslation = 0.1;  // [m] one IRLS step never moves a label further
constexpr double kMotionMaxStepRotation = 0.1;     // [rad]
constexpr double kMotionMaxDamping = 1e6;

/// @brief What the step control keeps per motion label between IRLS iterations.
struct MotionLabelControl {
  double accepted_cost;      ///< the label's cost at its last accepted twist (infinity before the first)
  double damping;            ///< Levenberg-Marquardt factor on the diagonal of the label's block
  double accepted_twist[6];  ///< the last twist whose cost was accepted
};

MCFLOW_HOST_DEVICE inline void startMotionLabelControl(const double twist[6], double damping, MotionLabelControl& c) {
  c.accepted_cost = INFINITY;
  c.damping = damping;
  for (int k = 0; k < 6; ++k) c.accepted_twist[k] = twist[k];
}

/// @brief Accepts or undoes a label's last step from the cost at its current twist. Returns true when the label
/// is frozen in this iteration (no update): too little support, or its cost rose, in which case the twist goes back
/// half way (the quadratic model overshot: residuals of textured images are linear over a fraction of a pixel only)
/// and the following solves are damped harder.
MCFLOW_HOST_DEVICE inline bool controlMotionLabel(double label_cost, double label_pixels, double min_label_pixels,
                                                  double min_damping, double twist[6], MotionLabelControl& c) {
  if (label_pixels < min_label_pixels) return true;
  if (label_cost > c.accepted_cost * (1.0 + kMotionRejectRelativeIncrease)) {
    for (int k = 0; k < 6; ++k) twist[k] = c.accepted_twist[k] + 0.5 * (twist[k] - c.accepted_twist[k]);
    c.damping = c.damping * 4.0 < kMotionMaxDamping ? c.damping * 4.0 : kMotionMaxDamping;
    return true;
  }
  c.accepted_cost = label_cost;
  for (int k = 0; k < 6; ++k) c.accepted_twist[k] = twist[k];
  c.damping = c.damping / 3.0 > min_damping ? c.damping / 3.0 : min_damping;
  return false;
}

/// @brief A diagonal entry of a label's block after damping; `block_max` is the largest diagonal entry of the
/// block (a tiny ridge keeps directions without evidence solvable).
MCFLOW_HOST_DEVICE inline double dampedDiagonal(double h, double damping, double block_max) {
  return h + (damping * h + 1e-9 * (block_max > 1e-12 ? block_max : 1e-12));
}

/// @brief Whether two labels' motions are solved jointly in a step. `pair_diagonal` is the diagonal of their
/// off-diagonal block H_ab, `diagonal_a` / `diagonal_b` the damped diagonals of H_aa and H_bb. Blended pixels
/// couple them with strength max_r |H_ab(r,r)| / sqrt(H_aa(r,r) H_bb(r,r)) (at most about 1: the three blocks sum
/// the same positive semidefinite terms, weighted u_a u_b, u_a^2 and u_b^2); below `min_coupling` the coupling is
/// dropped from the step. With `min_coupling` 0 any non-zero entry of H_ab (`any_entry`) couples them.
MCFLOW_HOST_DEVICE inline bool motionLabelsCoupled(const double pair_diagonal[6], bool any_entry,
                                                   const double diagonal_a[6], const double diagonal_b[6],
                                                   double min_coupling) {
  if (!any_entry) return false;
  if (min_coupling <= 0.0) return true;
  for (int r = 0; r < 6; ++r)
    if (pair_diagonal[r] * pair_diagonal[r] >= min_coupling * min_coupling * diagonal_a[r] * diagonal_b[r]) return true;
  return false;
}

/// @brief Scales a label's step into the trust region (metres / radians) and returns its largest entry.
MCFLOW_HOST_DEVICE inline double limitMotionStep(double d[6]) {
  const double translation = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const double rotation = std::sqrt(d[3] * d[3] + d[4] * d[4] + d[5] * d[5]);
  double scale = 1.0;
  if (translation / kMotionMaxStepTranslation > scale) scale = translation / kMotionMaxStepTranslation;
  if (rotation / kMotionMaxStepRotation > scale) scale = rotation / kMotionMaxStepRotation;
  double largest = 0.0;
  for (int k = 0; k < 6; ++k) {
    d[k] /= scale;
    const double a = std::fabs(d[k]);
    largest = a > largest ? a : largest;
  }
  return largest;
}

}  // namespace mc_flow
