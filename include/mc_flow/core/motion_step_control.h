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

/// @brief Packed lower triangle of a 6x6 matrix, row by row: the index of (r, c), c <= r.
MCFLOW_HOST_DEVICE inline int lowerIndex6(int r, int c) { return r * (r + 1) / 2 + c; }

/// @brief How a factor from choleskyLower6 keeps its diagonal: the pivots themselves (the host loop, which divides by
/// them) or their reciprocals from rsqrt (the GPU's device loop, where multiplying shortens the serial chains of the
/// one thread that handles a label). Steps and coupling strengths of the two forms differ by rounding: in the last bits
/// for well-conditioned blocks, more where a pivot is near its floor; a coupling decision differs only for a strength
/// within that rounding of motion_min_coupling.
enum class PivotForm { Pivot, Reciprocal };

namespace motion_detail {
template <PivotForm form>
MCFLOW_HOST_DEVICE inline double storedPivot(double d) {
  if constexpr (form == PivotForm::Pivot) {
    return std::sqrt(d);
  } else {
#if defined(__CUDA_ARCH__)
    return rsqrt(d);
#else
    return 1.0 / std::sqrt(d);
#endif
  }
}
template <PivotForm form>
MCFLOW_HOST_DEVICE inline double byPivot(double v, double stored) {
  if constexpr (form == PivotForm::Pivot)
    return v / stored;
  else
    return v * stored;
}
}  // namespace motion_detail

/// @brief Cholesky factor L (packed lower, 21 values) of a symmetric 6x6 block `A` (row-major), A = L L^T. A pivot
/// that rounding leaves at or below 1e-12 of its diagonal entry is raised to that floor (a nearly indefinite block
/// without damping still gives a finite factor). `form` says how the diagonal slots keep the pivots (PivotForm).
template <PivotForm form = PivotForm::Pivot>
MCFLOW_HOST_DEVICE inline void choleskyLower6(const double A[36], double L[21]) {
  MCFLOW_UNROLL
  for (int j = 0; j < 6; ++j) {
    double d = A[j * 6 + j];
    const double floor = 1e-12 * d;
    MCFLOW_UNROLL
    for (int k = 0; k < j; ++k) d -= L[lowerIndex6(j, k)] * L[lowerIndex6(j, k)];
    const double pivot = motion_detail::storedPivot<form>(d > floor ? d : floor);
    L[lowerIndex6(j, j)] = pivot;
    MCFLOW_UNROLL
    for (int i = j + 1; i < 6; ++i) {
      double v = A[i * 6 + j];
      MCFLOW_UNROLL
      for (int k = 0; k < j; ++k) v -= L[lowerIndex6(i, k)] * L[lowerIndex6(j, k)];
      L[lowerIndex6(i, j)] = motion_detail::byPivot<form>(v, pivot);
    }
  }
}

/// @brief Solves L L^T x = b with a factor from choleskyLower6 of the same form.
template <PivotForm form = PivotForm::Pivot>
MCFLOW_HOST_DEVICE inline void choleskySolve6(const double L[21], const double b[6], double x[6]) {
  double y[6];
  MCFLOW_UNROLL
  for (int i = 0; i < 6; ++i) {
    double v = b[i];
    MCFLOW_UNROLL
    for (int k = 0; k < i; ++k) v -= L[lowerIndex6(i, k)] * y[k];
    y[i] = motion_detail::byPivot<form>(v, L[lowerIndex6(i, i)]);
  }
  MCFLOW_UNROLL
  for (int i = 5; i >= 0; --i) {
    double v = y[i];
    MCFLOW_UNROLL
    for (int k = i + 1; k < 6; ++k) v -= L[lowerIndex6(k, i)] * x[k];
    x[i] = motion_detail::byPivot<form>(v, L[lowerIndex6(i, i)]);
  }
}

/// @brief How strongly blended pixels couple the steps of labels a and b: the Frobenius norm of
/// L_a^-1 H_ab L_b^-T, where L_a L_a^T and L_b L_b^T are the damped diagonal blocks (choleskyLower6 of the same form)
/// and `pair` is the off-diagonal block H_ab (row-major). Its singular values are the canonical correlations of the two
/// labels' steps, in every direction of the twists, not only along the axes: a direction that a label's own pixels
/// hardly constrain and its blended pixels do shows up here (0: independent; the largest singular value is below 1 for
/// a positive definite system, the norm at most sqrt(6)).
template <PivotForm form = PivotForm::Pivot>
MCFLOW_HOST_DEVICE inline double motionCouplingStrength(const double L_a[21], const double pair[36],
                                                        const double L_b[21]) {
  double X[36];  // L_a^-1 H_ab, column by column
  MCFLOW_UNROLL
  for (int j = 0; j < 6; ++j) {
    MCFLOW_UNROLL
    for (int i = 0; i < 6; ++i) {
      double v = pair[i * 6 + j];
      MCFLOW_UNROLL
      for (int k = 0; k < i; ++k) v -= L_a[lowerIndex6(i, k)] * X[k * 6 + j];
      X[i * 6 + j] = motion_detail::byPivot<form>(v, L_a[lowerIndex6(i, i)]);
    }
  }
  double sum = 0.0;
  MCFLOW_UNROLL
  for (int i = 0; i < 6; ++i) {  // row i of X L_b^-T: L_b m = (row i of X)^T
    double m[6];
    MCFLOW_UNROLL
    for (int j = 0; j < 6; ++j) {
      double v = X[i * 6 + j];
      MCFLOW_UNROLL
      for (int k = 0; k < j; ++k) v -= L_b[lowerIndex6(j, k)] * m[k];
      m[j] = motion_detail::byPivot<form>(v, L_b[lowerIndex6(j, j)]);
      sum += m[j] * m[j];
    }
  }
  return std::sqrt(sum);
}

/// @brief Whether a coupling joins two labels' groups, whose motions are then solved jointly in a step: its strength
/// (motionCouplingStrength) reaches `min_coupling`; below it, the coupling is dropped from the step unless other
/// couplings put both labels in one group. With `min_coupling` 0 any non-zero entry of H_ab (`any_entry`) couples.
MCFLOW_HOST_DEVICE inline bool motionLabelsCoupled(double strength, bool any_entry, double min_coupling) {
  if (!any_entry) return false;
  return min_coupling <= 0.0 || strength >= min_coupling;
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
