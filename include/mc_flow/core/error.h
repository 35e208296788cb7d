/**
 * @file error.h
 * @brief Exceptions thrown by the core. Messages name the offending value.
 */
#pragma once

#include <stdexcept>
#include <string>

namespace mc_flow {

/// @brief Bad input data (sizes, encodings, invalid depth, intrinsics).
struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// @brief A Config value out of its valid range.
struct ConfigError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// @brief A backend that cannot run here (e.g. CUDA requested without a usable GPU).
struct BackendError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace mc_flow
