/**
 * @file motion_estimation_pixel.h
 * @brief The motion step's per-pixel rules, written once for the CPU accumulator (src/core/motion_estimation.cpp)
 * and the CUDA one (cuda/motion_estimation.cu): which pixels and labels take part, the warp's projection and
 * in-view test, the residuals, their Cauchy weights and costs and their Jacobians. Each backend sums the products
 * its own way (Eigen on the CPU, warp shuffles on the GPU).
 *
 * Rounding: the decisions (mass, active labels, in view, depth jump) and the residuals use explicitly rounded float
 * operations (rounded.h), so both backends decide alike bit for bit; the Jacobian rows are plain float arithmetic,
 * which nvcc may contract into FMAs (a few float ulps per pixel; test/cuda/test_motion_estimation_cuda.cpp states
 * the tolerances).
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/rounded.h"
#include "mc_flow/core/sampling.h"
#include "mc_flow/core/se3_coefficients.h"

namespace mc_flow {
namespace motion_pixel {

constexpr float kDepthEdgeJump = 0.1f;  // [m] depth samples straddling a larger jump carry no geometric residual
constexpr float kMinMass = 0.05f;       // pixels with less motion-label mass carry no residual
constexpr float kMinDepth = 1e-3f;      // [m] a warped point nearer than this is behind the camera (out of view)

/// @brief Whether a pixel with this much motion-label mass (sum of u over the motion labels) takes part.
MCFLOW_HOST_DEVICE inline bool usableMass(float mass) { return !(mass < kMinMass); }

/// @brief A label's interpolation weight before the active labels are renormalised: u_i / mass; the label is
/// active where this reaches Config::min_label_weight.
MCFLOW_HOST_DEVICE inline float labelShare(float u, float mass) { return divRn(u, mass); }

/// @brief The warped point's projection into frame 2 and its derivatives with respect to P2.
struct Projection {
  float inv_z;  ///< 1 / max(z, kMinDepth)
  float u, v;   ///< [px], clamped into the image within kBorderMargin (sampling.h)
  float du_dX, du_dZ, dv_dY, dv_dZ;
};

/// @brief Projects P2 with (fx, fy, cx, cy); false when it is behind the camera or out of view (clampIntoView).
MCFLOW_HOST_DEVICE inline bool project(const float P2[3], float fx, float fy, float cx, float cy, int width, int height,
                                       Projection& p) {
  p.inv_z = divRn(1.f, P2[2] < kMinDepth ? kMinDepth : P2[2]);
  p.u = addRn(mulRn(mulRn(fx, P2[0]), p.inv_z), cx);
  p.v = addRn(mulRn(mulRn(fy, P2[1]), p.inv_z), cy);
  const bool in_view = P2[2] >= kMinDepth && clampIntoView(width, height, p.u, p.v);
  p.du_dX = mulRn(fx, p.inv_z);
  p.du_dZ = mulRn(mulRn(mulRn(-fx, P2[0]), p.inv_z), p.inv_z);
  p.dv_dY = mulRn(fy, p.inv_z);
  p.dv_dZ = mulRn(mulRn(mulRn(-fy, P2[1]), p.inv_z), p.inv_z);
  return in_view;
}

/// @brief d r_I / d P2 for the intensity residual r_I = I1 - I2(warp), from frame 2's gradient (gx, gy) there.
MCFLOW_HOST_DEVICE inline void intensityRow(const Projection& p, float gx, float gy, float row[3]) {
  row[0] = -gx * p.du_dX;
  row[1] = -gy * p.dv_dY;
  row[2] = -(gx * p.du_dZ + gy * p.dv_dZ);
}

/// @brief d r_Z / d P2 for the depth residual r_Z = Z2' - Z2(warp), from frame 2's depth gradient (gx, gy) there.
MCFLOW_HOST_DEVICE inline void depthRow(const Projection& p, float gx, float gy, float row[3]) {
  row[0] = -gx * p.du_dX;
  row[1] = -gy * p.dv_dY;
  row[2] = 1.f - (gx * p.du_dZ + gy * p.dv_dZ);
}

/// @brief A residual's Jacobian with respect to the twist: the left increment eps (exp(eps) exp(xi_bar)) moves P2
/// by d_eps_v + d_eps_w x P2, so row * [I | -skew(P2)]; an additive twist increment maps to eps through the left
/// Jacobian of SE(3) (`left_jacobian`, row-major 6x6): out = J_l^T (row * [I | -skew(P2)])^T. Each entry sums its six
/// products as ((p0 + p2) + (p1 + p3)) + (p4 + p5), the order of the CPU's Eigen product (SSE packets of four) that
/// this replaced, so the CPU keeps its bits.
MCFLOW_HOST_DEVICE inline void residualJacobian(const float P2[3], const float row[3], const float* left_jacobian,
                                                float out[6]) {
  const float point[6] = {row[0],
                          row[1],
                          row[2],
                          row[2] * P2[1] - row[1] * P2[2],
                          row[0] * P2[2] - row[2] * P2[0],
                          row[1] * P2[0] - row[0] * P2[1]};
  MCFLOW_UNROLL
  for (int i = 0; i < 6; ++i) {
    float p[6];
    MCFLOW_UNROLL
    for (int r = 0; r < 6; ++r) p[r] = left_jacobian[r * 6 + i] * point[r];
    out[i] = ((p[0] + p[2]) + (p[1] + p[3])) + (p[4] + p[5]);
  }
}

/// @brief IRLS weight of the normalised Cauchy cost factor * ln(1 + (r/c)^2): factor / (c^2 + r^2).
MCFLOW_HOST_DEVICE inline float cauchyWeight(float factor, float c, float r) {
  return divRn(factor, addRn(mulRn(c, c), mulRn(r, r)));
}

/// @brief The Cauchy scale of a depth residual where frame 2's depth is Z2 (Config::depth_noise_reference): c_depth up
/// to `reference`, c_depth (Z2 / reference)^2 beyond it; c_depth everywhere when `reference` is 0.
MCFLOW_HOST_DEVICE inline float depthCauchyScale(float c_depth, float reference, float Z2) {
  if (!(reference > 0.f)) return c_depth;
  const float ratio = divRn(Z2, reference);
  const float growth = mulRn(ratio, ratio);
  return growth > 1.f ? mulRn(c_depth, growth) : c_depth;
}

/// @brief The normalised Cauchy cost ln(1 + (r/c)^2) of a residual, in float.
MCFLOW_HOST_DEVICE inline float cauchyCost(float c, float r) { return log1pF(divRn(mulRn(r, r), mulRn(c, c))); }

/// @brief A pixel's cost without depth evidence: alpha ln 2, a constant, so that costs stay comparable.
MCFLOW_HOST_DEVICE inline double missingDepthCost(float alpha) { return double(alpha) * 0.69314718055994530942; }

}  // namespace motion_pixel
}  // namespace mc_flow
