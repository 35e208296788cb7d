#include "mc_flow/core/se3.h"

#include "mc_flow/core/se3_coefficients.h"

#include <cmath>

namespace mc_flow {

Eigen::Matrix3d skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d S;
  S << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return S;
}

// Closed forms (Rodrigues); Taylor expansions below 1e-8 rad keep small motions exact in double precision.
Eigen::Matrix4d se3Exp(const Vector6d& xi) {
  const Eigen::Vector3d v = xi.head<3>(), w = xi.tail<3>();
  const Eigen::Matrix3d W = skew(w), W2 = W * W;
  double a, b, c;  // R = I + a W + b W^2, V = I + b W + c W^2
  se3ExpCoefficients(w.squaredNorm(), a, b, c);
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity() + a * W + b * W2;
  T.topRightCorner<3, 1>() = (Eigen::Matrix3d::Identity() + b * W + c * W2) * v;
  return T;
}

Matrix6d se3Adjoint(const Eigen::Matrix4d& T) {
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  Matrix6d A = Matrix6d::Zero();
  A.topLeftCorner<3, 3>() = R;
  A.topRightCorner<3, 3>() = skew(T.topRightCorner<3, 1>()) * R;
  A.bottomRightCorner<3, 3>() = R;
  return A;
}

Vector6d se3Log(const Eigen::Matrix4d& T) {
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::AngleAxisd aa(R);
  const double theta = aa.angle();
  const Eigen::Vector3d w = aa.axis() * theta;
  const Eigen::Matrix3d W = skew(w), W2 = W * W;
  Eigen::Matrix3d Vinv;
  if (theta < 1e-8) {
    Vinv = Eigen::Matrix3d::Identity() - 0.5 * W + W2 / 12.0;
  } else {
    const double half = 0.5 * theta;
    const double k = (1.0 - half * std::cos(half) / std::sin(half)) / (theta * theta);
    Vinv = Eigen::Matrix3d::Identity() - 0.5 * W + k * W2;
  }
  Vector6d xi;
  xi.head<3>() = Vinv * T.topRightCorner<3, 1>();
  xi.tail<3>() = w;
  return xi;
}

Matrix6d se3LeftJacobian(const Vector6d& xi) {
  // Barfoot, State Estimation for Robotics (2017), eqs. 7.83 and 7.86: J = [[J_SO3, Q], [0, J_SO3]].
  const Eigen::Vector3d rho = xi.head<3>(), phi = xi.tail<3>();
  const Eigen::Matrix3d F = skew(phi), F2 = F * F, P = skew(rho);
  double a, b, c, d;  // J_SO3 = I + a F + b F^2; Q uses b, c, d
  se3LeftJacobianCoefficients(phi.squaredNorm(), a, b, c, d);
  const Eigen::Matrix3d J = Eigen::Matrix3d::Identity() + a * F + b * F2;
  const Eigen::Matrix3d Q = 0.5 * P + b * (F * P + P * F + F * P * F) + c * (F2 * P + P * F2 - 3.0 * F * P * F) +
                            d * (F * P * F2 + F2 * P * F);
  Matrix6d out = Matrix6d::Zero();
  out.topLeftCorner<3, 3>() = J;
  out.topRightCorner<3, 3>() = Q;
  out.bottomRightCorner<3, 3>() = J;
  return out;
}

}  // namespace mc_flow
