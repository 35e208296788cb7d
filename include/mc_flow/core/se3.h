/**
 * @file se3.h
 * @brief Twists and rigid transforms: exp/log on SE(3).
 *
 * A twist is (v, w): v [m] first, w [rad] second; T = exp(hat(xi)) maps points of frame 1 into the
 * camera frame of frame 2 (points move with the scene).
 */
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace mc_flow {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// @brief exp: twist (v, w) -> 4x4 rigid transform.
Eigen::Matrix4d se3Exp(const Vector6d& xi);
/// @brief log: 4x4 rigid transform -> twist (v, w); inverse of se3Exp for rotation angles < pi.
Vector6d se3Log(const Eigen::Matrix4d& T);
/// @brief Left Jacobian of SE(3) (ordering (v, w)): exp(hat(xi + d)) = exp(hat(J d)) exp(hat(xi)) to first
/// order in d. Lets the motion step update twists additively with the exact first-order Jacobian.
Matrix6d se3LeftJacobian(const Vector6d& xi);
/// @brief Skew-symmetric matrix of w (hat(w) x = w cross x).
Eigen::Matrix3d skew(const Eigen::Vector3d& w);
/// @brief Adjoint of a rigid transform T = (R, t) on twists (v, w): [[R, [t]x R], [0, R]]; T exp(d) T^-1 = exp(Ad_T d).
Matrix6d se3Adjoint(const Eigen::Matrix4d& T);

}  // namespace mc_flow
