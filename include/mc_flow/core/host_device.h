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
