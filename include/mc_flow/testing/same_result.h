/**
 * @file same_result.h
 * @brief Whether two solves of the same pair gave the same result byte for byte (NaN equals NaN, 0.0 is not -0.0):
 * for the benchmarks' and tests' checks that a solver gives the same bits alone, beside others or on another device.
 */
#pragma once

#include <string>

#include "mc_flow/core/solver.h"

namespace mc_flow {

/// @brief The first output in which `a` and `b` differ byte for byte ("size", "label count", "labels", "soft labels",
/// "scene flow", "optical flow", "moved depth", "occlusion", "segment count (3 against 4)", "segment 2's twist" (id,
/// twist, transform, support, covariance), "the static world's twist"); empty when none does.
std::string firstDifference(const Result& a, const Result& b);

}  // namespace mc_flow
