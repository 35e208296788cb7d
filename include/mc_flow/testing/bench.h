/**
 * @file bench.h
 * @brief What the benchmark tools share besides their command line (mc_flow/cli/command_line.h, the parser of every
 * mc_flow executable, included here): the choice of regularisers. The median of timings they print is
 * mc_flow::median (mc_flow/eval/metrics.h, shared with `mcflow bench-real`).
 *
 * Core only (no OpenCV), like the tools that use it, so that it builds on the GPU machine. Benchmark harness:
 * library mc_flow_testing, linked by the benchmarks and the tests only, not installed.
 */
#pragma once

#include <string>
#include <vector>

#include "mc_flow/cli/command_line.h"
#include "mc_flow/core/config.h"
#include "mc_flow/eval/metrics.h"

namespace mc_flow {

/// @brief "both" (quadratic, then TV), or one regulariser by Config's names; throws ConfigError otherwise.
std::vector<Regularizer> regularizerChoice(const std::string& text);

}  // namespace mc_flow
