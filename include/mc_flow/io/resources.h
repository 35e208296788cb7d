/**
 * @file resources.h
 * @brief What a solve of a given size will cost, so that `mcflow run` can warn before a slow solve and
 * refuse one that would not fit in memory, instead of running for minutes without a word.
 *
 * The memory model is measured, not derived: peak RSS of `mcflow run` (CPU backend) at 640x480 and
 * 1280x960, processing levels 0 and 1, 5 and 20 initial labels, fitted within 7%, and 2560x1920 (1.98 GB)
 * predicted within 1%. It covers the
 * full-resolution images, outputs and pictures (per input pixel) and the solver's buffers (per processing
 * pixel, growing with the label count).
 */
#pragma once

#include <cstdint>
#include <string>

#include "mc_flow/core/config.h"

namespace mc_flow {
namespace io {

/// @brief Width and height the solver works at: the input halved `processing_level` times (rounded up).
struct ProcessingSize {
  int width = 0, height = 0;
  double pixels() const { return double(width) * double(height); }
};
ProcessingSize processingSize(int width, int height, int processing_level);

/// @brief Estimated peak memory [bytes] of `mcflow run` on a width x height pair with `config`.
std::uint64_t estimateRunBytes(int width, int height, const Config& config);

/// @brief Estimated CPU solve time [s] on 2 cores (measured: about 15 s per million processing pixels).
double estimateCpuSolveSeconds(int width, int height, const Config& config);

/// @brief MemAvailable [bytes] from the text of /proc/meminfo; 0 when it is not there.
std::uint64_t parseMemAvailable(const std::string& meminfo);

/// @brief MemAvailable [bytes] of this machine (/proc/meminfo); 0 when unknown.
std::uint64_t availableMemoryBytes();

/// @brief Above this many processing pixels (about 1630x1230) a CPU solve takes half a minute or more.
constexpr double kSlowProcessingPixels = 2.0e6;

/// @brief The verdict on a pair's size before solving.
struct SizeCheck {
  std::string warning;  ///< non-empty: slow on the CPU; says how slow and which --processing-level helps
  std::string error;    ///< non-empty: would not fit in `available_bytes`; names both amounts
};

/// @brief Checks a width x height solve against the slowness threshold (when `cpu`) and against
/// `available_bytes` (skipped when 0, i.e. unknown).
SizeCheck checkRunSize(int width, int height, const Config& config, bool cpu, std::uint64_t available_bytes);

/// @brief "18.7 GB", or "540 MB" below a gigabyte (decimal units).
std::string formatBytes(std::uint64_t bytes);

}  // namespace io
}  // namespace mc_flow
