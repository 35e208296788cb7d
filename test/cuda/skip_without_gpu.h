// The CUDA tests skip, visibly and with the reason, where no usable GPU is present (CI has none).
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "mc_flow/core/solve_backend.h"

#define SKIP_WITHOUT_GPU()                                                                                         \
  do {                                                                                                             \
    std::string why_no_gpu;                                                                                        \
    if (!::mc_flow::cudaBackendAvailable(&why_no_gpu)) GTEST_SKIP() << "CUDA backend unavailable: " << why_no_gpu; \
  } while (0)
