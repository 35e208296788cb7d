/**
 * @file rounded.h
 * @brief Float arithmetic rounded operation by operation, for the per-pixel functions that the CPU stages and
 * the CUDA kernels share. nvcc would otherwise contract a * b + c into one FMA (one rounding instead of two);
 * the CPU build (x86-64 baseline, no FMA) rounds every operation, so with these both compute the same bits.
 */
#pragma once

#include <cmath>

#include "mc_flow/core/host_device.h"

// The device intrinsic in device code, the host expression elsewhere: one definition of each rounded operation.
#if defined(__CUDA_ARCH__)
#define MCFLOW_DEVICE_OR_HOST(device, host) (device)
#else
#define MCFLOW_DEVICE_OR_HOST(device, host) (host)
#endif

namespace mc_flow {

MCFLOW_HOST_DEVICE inline float addRn(float a, float b) { return MCFLOW_DEVICE_OR_HOST(__fadd_rn(a, b), a + b); }

MCFLOW_HOST_DEVICE inline float subRn(float a, float b) { return MCFLOW_DEVICE_OR_HOST(__fsub_rn(a, b), a - b); }

MCFLOW_HOST_DEVICE inline float mulRn(float a, float b) { return MCFLOW_DEVICE_OR_HOST(__fmul_rn(a, b), a * b); }

MCFLOW_HOST_DEVICE inline float divRn(float a, float b) { return MCFLOW_DEVICE_OR_HOST(__fdiv_rn(a, b), a / b); }

MCFLOW_HOST_DEVICE inline float absF(float a) { return a < 0.f ? -a : a; }

/// @brief std::max(a, b): b when a < b, else a (NaN in b gives a), as the CPU's std::max.
MCFLOW_HOST_DEVICE inline float maxF(float a, float b) { return a < b ? b : a; }

/// @brief IEEE-rounded square root on both sides.
MCFLOW_HOST_DEVICE inline float sqrtRn(float a) { return MCFLOW_DEVICE_OR_HOST(__fsqrt_rn(a), std::sqrt(a)); }

/// @brief std::isfinite of a float on both sides.
MCFLOW_HOST_DEVICE inline bool finiteF(float a) { return MCFLOW_DEVICE_OR_HOST(isfinite(a), std::isfinite(a)); }

/// @brief ln(1 + x) of a float, in float (the host's std::log1p(float), the device's log1pf).
MCFLOW_HOST_DEVICE inline float log1pF(float x) { return MCFLOW_DEVICE_OR_HOST(log1pf(x), std::log1p(x)); }

}  // namespace mc_flow
