/**
 * @file rounded.h
 * @brief Float arithmetic rounded operation by operation, for the per-pixel functions that the CPU stages and
 * the CUDA kernels share. nvcc would otherwise contract a * b + c into one FMA (one rounding instead of two);
 * the CPU build (x86-64 baseline, no FMA) rounds every operation, so with these both compute the same bits.
 */
#pragma once

#include "mc_flow/core/host_device.h"

namespace mc_flow {

MCFLOW_HOST_DEVICE inline float addRn(float a, float b) {
#if defined(__CUDA_ARCH__)
  return __fadd_rn(a, b);
#else
  return a + b;
#endif
}

MCFLOW_HOST_DEVICE inline float subRn(float a, float b) {
#if defined(__CUDA_ARCH__)
  return __fsub_rn(a, b);
#else
  return a - b;
#endif
}

MCFLOW_HOST_DEVICE inline float mulRn(float a, float b) {
#if defined(__CUDA_ARCH__)
  return __fmul_rn(a, b);
#else
  return a * b;
#endif
}

MCFLOW_HOST_DEVICE inline float divRn(float a, float b) {
#if defined(__CUDA_ARCH__)
  return __fdiv_rn(a, b);
#else
  return a / b;
#endif
}

MCFLOW_HOST_DEVICE inline float absF(float a) { return a < 0.f ? -a : a; }

}  // namespace mc_flow
