/**
 * @file union_refit_step.h
 * @brief The step control of refitUnions (one motion refitted on the union of a group of labels: the merge test and
 * the static world's fit), shared by the host loop (label_adaptation.cpp, Eigen's LDLT) and the CUDA backend's loop on
 * the device (cuda/motion_estimation.cu, its own Cholesky): the ridge, the damping's start and its updates, and the
 * step's limit.
 */
#pragma once

#include "mc_flow/core/host_device.h"

namespace mc_flow {
namespace union_refit {

/// Relative ridge on the 6x6 solves (times the largest diagonal entry of H): a planar or textureless segment leaves
/// directions unconstrained.
constexpr double kRidge = 1e-6;
/// The largest translation [m] and rotation [rad] of one step: larger steps are scaled down as a whole.
constexpr double kMaxTranslation = 0.1, kMaxRotation = 0.1;

/// The damping after an accepted step: a third, not below the motion step's `min_damping`.
MCFLOW_HOST_DEVICE inline double dampingAfterAccept(double damping, double min_damping) {
  const double d = damping / 3.0;
  return d > min_damping ? d : min_damping;
}

/// The damping after a rejected step (the cost rose, or the step was not finite): four times, at least 1e-3.
MCFLOW_HOST_DEVICE inline double dampingAfterReject(double damping) {
  const double d = damping * 4.0;
  return d > 1e-3 ? d : 1e-3;
}

}  // namespace union_refit
}  // namespace mc_flow
