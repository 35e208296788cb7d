/**
 * @file soak.h
 * @brief What the soak benchmark (mcflow_bench_soak) measures and how it judges it: the process's resident set
 * size, and whether a series of memory samples stayed flat after a warm-up. Core only (no OpenCV), like the tool.
 */
#pragma once

#include <string>
#include <vector>

namespace mc_flow {

/// @brief A field of /proc/self/status in bytes ("VmRSS", "VmHWM", ...; the file gives kB); -1 where it cannot
/// be read (not Linux, or no such field).
double processStatusBytes(const std::string& field);

/// @brief Memory in use [bytes] after `solves` solves.
struct MemorySample {
  long solves = 0;
  double bytes = 0;
};

/// @brief The flatness rule. The samples taken at or after `warmup_solves` are split in thirds (at least one sample
/// each): the baseline is the median of the first third, the end level the median of the last third, and the series
/// is flat when the end level exceeds the baseline by no more than `tolerance_bytes`. Medians, so that one allocator
/// peak does not decide, while a steady leak moves the whole last third. The peak and the least-squares trend are
/// reported, not judged.
struct FlatnessVerdict {
  bool judged = false;  ///< false: fewer than two samples at or after the warm-up (no verdict)
  bool flat = false;
  long first_solves = 0, last_solves = 0;  ///< the samples judged: from, to
  double baseline = 0, end = 0, peak = 0;  ///< [bytes]
  double growth = 0;                       ///< end - baseline [bytes]
  double slope_per_1000 = 0;               ///< least-squares trend [bytes per 1000 solves]
};

FlatnessVerdict judgeFlatness(const std::vector<MemorySample>& samples, long warmup_solves, double tolerance_bytes);

}  // namespace mc_flow
