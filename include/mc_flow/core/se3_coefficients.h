/**
 * @file se3_coefficients.h
 * @brief The scalar coefficients of SE(3)'s closed forms (Rodrigues' exp and Barfoot's left Jacobian), with their
 * series near zero, written once for the host (se3.cpp, which assembles Eigen matrices from them) and the CUDA
 * kernels (which assemble row-major arrays); the per-pixel stages' exp of a blended twist (se3ExpRows) and the
 * transform of a point in float (transformPoint), shared by the CPU stages and the kernels.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/rounded.h"

namespace mc_flow {

/// @brief exp(xi) = [R V v; 0 1] with R = I + a W + b W^2 and V = I + b W + c W^2, W = skew(w), for
/// theta2 = |w|^2. Taylor series below 1e-8 rad keep small motions exact in double precision.
MCFLOW_HOST_DEVICE inline void se3ExpCoefficients(double theta2, double& a, double& b, double& c) {
  const double theta = std::sqrt(theta2);
  if (theta < 1e-8) {
    a = 1.0 - theta2 / 6.0;
    b = 0.5 - theta2 / 24.0;
    c = 1.0 / 6.0 - theta2 / 120.0;
  } else {
    a = std::sin(theta) / theta;
    b = (1.0 - std::cos(theta)) / theta2;
    c = (theta - std::sin(theta)) / (theta2 * theta);
  }
}

/// @brief Left Jacobian of SE(3) (Barfoot, State Estimation for Robotics, 2017, eqs. 7.83 and 7.86):
/// J = [[J_SO3, Q], [0, J_SO3]] with J_SO3 = I + a F + b F^2 and
/// Q = P/2 + b (FP + PF + FPF) + c (F^2 P + P F^2 - 3 FPF) + d (FPF^2 + F^2 PF), F = skew(phi), P = skew(rho), for
/// t2 = |phi|^2. Series below 1e-3 rad: the closed forms cancel to ~t^5 there.
MCFLOW_HOST_DEVICE inline void se3LeftJacobianCoefficients(double t2, double& a, double& b, double& c, double& d) {
  const double t = std::sqrt(t2);
  if (t < 1e-3) {
    a = 0.5 - t2 / 24.0;
    b = 1.0 / 6.0 - t2 / 120.0;
    c = 1.0 / 24.0 - t2 / 720.0;
    d = 1.0 / 120.0 - t2 / 2520.0;
  } else {
    const double s = std::sin(t), co = std::cos(t);
    a = (1.0 - co) / t2;
    b = (t - s) / (t2 * t);
    c = (t2 + 2.0 * co - 2.0) / (2.0 * t2 * t2);
    d = (2.0 * t - 3.0 * s + t * co) / (2.0 * t2 * t2 * t);
  }
}

/// @brief Rows 0..2 of exp(xi) (row-major 3x4) in double, xi = (v, w): R = I + a W + b W^2 and t = (I + b W + c W^2) v,
/// each entry in the order of se3.cpp's Eigen expressions (W^2 and the product with v summed over k = 0, 1, 2), so
/// that the host gets se3Exp's bits.
MCFLOW_HOST_DEVICE inline void se3ExpRows(const double xi[6], double T[12]) {
  const double* v = xi;
  const double* w = xi + 3;
  const double W[9] = {0, -w[2], w[1], w[2], 0, -w[0], -w[1], w[0], 0};
  double W2[9];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) W2[r * 3 + c] = W[r * 3] * W[c] + W[r * 3 + 1] * W[3 + c] + W[r * 3 + 2] * W[6 + c];
  double a, b, c;
  se3ExpCoefficients(w[0] * w[0] + w[1] * w[1] + w[2] * w[2], a, b, c);
  for (int r = 0; r < 3; ++r) {
    double V[3];
    for (int k = 0; k < 3; ++k) {
      const double identity = r == k ? 1.0 : 0.0;
      T[r * 4 + k] = identity + a * W[r * 3 + k] + b * W2[r * 3 + k];
      V[k] = identity + b * W[r * 3 + k] + c * W2[r * 3 + k];
    }
    T[r * 4 + 3] = V[0] * v[0] + V[1] * v[1] + V[2] * v[2];
  }
}

/// @brief P2 = R P + t for a row-major 3x4 float transform, rounded as the CPU's Eigen product of the points:
/// a0 x + (a1 y + a2 z), then + t (explicitly rounded operations, no FMA).
MCFLOW_HOST_DEVICE inline void transformPoint(const float T[12], const float P[3], float P2[3]) {
  MCFLOW_UNROLL
  for (int r = 0; r < 3; ++r) {
    const float* row = T + 4 * r;
    P2[r] = addRn(addRn(mulRn(row[0], P[0]), addRn(mulRn(row[1], P[1]), mulRn(row[2], P[2]))), row[3]);
  }
}

}  // namespace mc_flow
