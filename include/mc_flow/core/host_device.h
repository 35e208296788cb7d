/**
 * @file host_device.h
 * @brief MCFLOW_HOST_DEVICE: marks small functions that the CPU code and the CUDA kernels share, so both
 * compute the same results from one definition.
 */
#pragma once

#if defined(__CUDACC__)
#define MCFLOW_HOST_DEVICE __host__ __device__
#else
#define MCFLOW_HOST_DEVICE
#endif

// MCFLOW_UNROLL: unrolls the next loop in device code (the host compiler decides for itself).
#if defined(__CUDA_ARCH__)
#define MCFLOW_UNROLL _Pragma("unroll")
#else
#define MCFLOW_UNROLL
#endif
