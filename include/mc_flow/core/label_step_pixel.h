/**
 * @file label_step_pixel.h
 * @brief The label step's per-pixel rules, written once for the CPU (src/core/label_optimization.cpp) and the CUDA
 * kernels (cuda/label_optimization.cu): the geometric weight between neighbours (eq. 11), a motion label's data
 * cost (eq. 5), the diagonal preconditioners, and the dual and primal updates of the primal-dual iteration. Each
 * backend loops over pixels and labels its own way (vectorised rows with OpenMP on the CPU, a thread per pixel and
 * label on the GPU) and reduces the largest change its own way.
 *
 * Rounding: every float operation is rounded on its own (rounded.h) in the order the CPU evaluates it, so both
 * backends compute the same bits except for log1p (log1pF: the device's log1pf in the data costs).
 * The derivation is in docs/ALGORITHM.md.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/config.h"
#include "mc_flow/core/host_device.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/motion_estimation_pixel.h"
#include "mc_flow/core/rounded.h"
#include "mc_flow/core/sampling.h"

namespace mc_flow {
namespace label_pixel {

constexpr float kMinDepth = 1e-3f;    ///< [m] a warped point at or nearer than this is out of view (data cost)
constexpr float kNoColumnTau = 1e3f;  ///< tau of a pixel whose column of K is empty (no neighbour carries weight)

/// @brief Geometric weight (eq. 11) between the frame-1 points (x0, y0, z0) and (x1, y1, z1) of two neighbours:
/// r = footprint / max(footprint, distance), at least wmin; 1 on a fronto-parallel surface at any depth and
/// resolution, falling as 1/distance across depth discontinuities (the paper's inverse 3D distance, normalised).
/// fmean = (fx + fy) / 2 of the level; wmin where either point has no depth.
MCFLOW_HOST_DEVICE inline float geometricWeight(float x0, float y0, float z0, float x1, float y1, float z1, float fmean,
                                                float wmin) {
  if (!finiteF(z0) || !finiteF(z1)) return wmin;
  const float dx = subRn(x0, x1), dy = subRn(y0, y1), dz = subRn(z0, z1);
  const float distance = sqrtRn(addRn(addRn(mulRn(dx, dx), mulRn(dy, dy)), mulRn(dz, dz)));
  const float footprint = divRn(mulRn(0.5f, addRn(z0, z1)), fmean);
  return maxF(wmin, divRn(footprint, maxF(footprint, distance)));
}

/// @brief fmean of geometricWeight for a level's intrinsics.
inline float geometricWeightFocal(const Intrinsics& K) { return float(0.5 * (K.fx + K.fy)); }

/// @brief The constants of a motion label's data cost at one level.
struct DataCostTerms {
  float fx, fy, cx, cy;         ///< frame 2's intrinsics [px]
  float c_intensity, c_depth;   ///< Cauchy scales
  float depth_noise_reference;  ///< [m] where the depth scale starts to grow (motion_pixel::depthCauchyScale)
  float alpha;                  ///< weight of the depth term
  float out_of_view;            ///< cost of a warp behind the camera or out of view
  float missing_depth;          ///< cost of the depth term without a depth sample: as if |r_Z| = c_Z
};

/// @brief The data cost's constants from frame 2's intrinsics K at the level and the Config (on the host, for both
/// backends). Without a depth sample the depth term is alpha log 2, as if |r_Z| = c_Z: no evidence either way.
inline DataCostTerms dataCostTerms(const Intrinsics& K, const Config& config) {
  DataCostTerms t;
  t.fx = float(K.fx);
  t.fy = float(K.fy);
  t.cx = float(K.cx);
  t.cy = float(K.cy);
  t.c_intensity = float(config.cauchy_c_intensity);
  t.c_depth = float(config.cauchy_c_depth);
  t.depth_noise_reference = float(config.depth_noise_reference);
  t.alpha = float(config.alpha);
  t.out_of_view = float(config.out_of_view_cost);
  t.missing_depth = t.alpha * std::log(2.f);
  return t;
}

/// @brief Data cost (eq. 5) of a motion label at a frame-1 pixel of intensity I1 whose point that label's motion
/// takes to P2: Cauchy costs of the intensity and depth residuals at P2's projection into frame 2, sampled through
/// the accessors `intensity2(xi, yi)` and `depth2(xi, yi)` of frame-2 images of width x height.
template <typename IntensityAt, typename DepthAt>
MCFLOW_HOST_DEVICE float motionLabelCost(const float P2[3], float I1, const IntensityAt& intensity2,
                                         const DepthAt& depth2, int width, int height, const DataCostTerms& t) {
  if (!(P2[2] > kMinDepth)) return t.out_of_view;
  float u = addRn(divRn(mulRn(t.fx, P2[0]), P2[2]), t.cx), v = addRn(divRn(mulRn(t.fy, P2[1]), P2[2]), t.cy);
  float I2, Z2;
  if (!clampIntoView(width, height, u, v) || !sampleBilinearAt(intensity2, width, height, u, v, I2))
    return t.out_of_view;
  const float rI = divRn(subRn(I1, I2), t.c_intensity);
  const float cost = log1pF(mulRn(rI, rI));
  if (!sampleDepthBilinearAt(depth2, width, height, u, v, Z2)) return addRn(cost, t.missing_depth);
  const float rZ = divRn(subRn(P2[2], Z2), motion_pixel::depthCauchyScale(t.c_depth, t.depth_noise_reference, Z2));
  return addRn(cost, mulRn(t.alpha, log1pF(mulRn(rZ, rZ))));
}

/// @brief A pixel's diagonal preconditioners (Pock & Chambolle 2011, alpha = 1), in the form the iteration uses.
struct StepSizes {
  float sigma_rx, sigma_ry;  ///< sigma times the weight of the forward difference, per direction
  float shrink_x, shrink_y;  ///< the quadratic prox p / (1 + sigma / (2 lambda)) as one factor
  float tau;                 ///< 1 / (column sum of |K|)
};

/// @brief Step sizes from the pixel's weights rx, ry and its left and upper neighbours' rx_left, ry_up (0 at the first
/// column/row). Row sums of |K| give sigma, column sums tau. TV projects p onto a disc, which is only the proximal map
/// when both components share one sigma: it takes the smaller of the two (a smaller step keeps the convergence
/// condition).
MCFLOW_HOST_DEVICE inline StepSizes stepSizes(float rx, float ry, float rx_left, float ry_up, bool tv, float lambda) {
  float sx = rx > 0.f ? divRn(1.f, mulRn(2.f, rx)) : 0.f;
  float sy = ry > 0.f ? divRn(1.f, mulRn(2.f, ry)) : 0.f;
  if (tv) {
    const float m = maxF(rx, ry);
    sx = sy = m > 0.f ? divRn(1.f, mulRn(2.f, m)) : 0.f;
  }
  StepSizes s;
  s.sigma_rx = mulRn(sx, rx);
  s.sigma_ry = mulRn(sy, ry);
  const float two_lambda = mulRn(2.f, lambda);
  s.shrink_x = divRn(1.f, addRn(1.f, divRn(sx, two_lambda)));
  s.shrink_y = divRn(1.f, addRn(1.f, divRn(sy, two_lambda)));
  const float column = addRn(addRn(addRn(rx, ry), rx_left), ry_up);
  s.tau = column > 0.f ? divRn(1.f, column) : kNoColumnTau;
  return s;
}

/// @brief Dual ascent of one component: p + sigma r (u_bar(next) - u_bar(here)).
MCFLOW_HOST_DEVICE inline float dualAscent(float p, float sigma_r, float difference) {
  return addRn(p, mulRn(sigma_r, difference));
}

/// @brief The quadratic regulariser's prox of an ascended component q.
MCFLOW_HOST_DEVICE inline float dualQuadratic(float q, float shrink) { return mulRn(q, shrink); }

/// @brief TV's prox of the ascended (qx, qy): the factor that projects it onto the disc of radius lambda.
MCFLOW_HOST_DEVICE inline float dualTvScale(float qx, float qy, float inv_lambda) {
  return divRn(1.f, maxF(1.f, mulRn(sqrtRn(addRn(mulRn(qx, qx), mulRn(qy, qy))), inv_lambda)));
}

/// @brief The weighted backward divergence of p at a pixel (K^T p = -divergence): the left and upper terms are 0
/// at the first column/row (pass rx_left = p_left = 0, ry_up = p_up = 0 there).
MCFLOW_HOST_DEVICE inline float divergence(float rx, float px, float ry, float py, float rx_left, float px_left,
                                           float ry_up, float py_up) {
  return subRn(subRn(addRn(mulRn(rx, px), mulRn(ry, py)), mulRn(rx_left, px_left)), mulRn(ry_up, py_up));
}

/// @brief Primal descent before the simplex projection: u - tau (K^T p + D).
MCFLOW_HOST_DEVICE inline float primalCandidate(float u, float tau, float divergence, float data_cost) {
  return subRn(u, mulRn(tau, addRn(-divergence, data_cost)));
}

/// @brief The extrapolation u_bar = 2 u_new - u_old (theta = 1).
MCFLOW_HOST_DEVICE inline float extrapolate(float u_new, float u_old) { return subRn(mulRn(2.f, u_new), u_old); }

/// @brief |u_new - u_old|, the convergence test's measure.
MCFLOW_HOST_DEVICE inline float change(float u_new, float u_old) { return absF(subRn(u_new, u_old)); }

}  // namespace label_pixel
}  // namespace mc_flow
