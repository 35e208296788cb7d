#include "mc_flow/io/resources.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "mc_flow/core/image.h"

namespace mc_flow {
namespace io {
namespace {

// Peak RSS = base + per input pixel + per processing pixel x (fixed + per initial label); see resources.h.
constexpr double kBaseBytes = 64.0 * 1024 * 1024;
constexpr double kBytesPerInputPixel = 190.0;
constexpr double kBytesPerProcessingPixel = 150.0;
constexpr double kBytesPerProcessingPixelAndLabel = 2.5;
constexpr double kCpuSecondsPerProcessingPixel = 15e-6;  // 1280x960 at level 0: 19 s on 2 cores
constexpr int kMaxSuggestedLevel = 6;

std::string durationText(double seconds) {
  char buffer[64];
  if (seconds < 90)
    std::snprintf(buffer, sizeof(buffer), "%.0f s", seconds);
  else
    std::snprintf(buffer, sizeof(buffer), "%.0f min", seconds / 60.0);
  return buffer;
}

Config atLevel(const Config& config, int level) {
  Config c = config;
  c.processing_level = level;
  return c;
}

}  // namespace

ProcessingSize processingSize(int width, int height, int processing_level) {
  ProcessingSize size{width, height};
  for (int l = 0; l < processing_level; ++l) {
    size.width = (size.width + 1) / 2;
    size.height = (size.height + 1) / 2;
  }
  return size;
}

std::uint64_t estimateRunBytes(int width, int height, const Config& config) {
  const double input_pixels = double(width) * double(height);
  const double processing_pixels = processingSize(width, height, config.processing_level).pixels();
  const double per_processing_pixel =
      kBytesPerProcessingPixel + kBytesPerProcessingPixelAndLabel * double(config.initial_labels);
  return std::uint64_t(kBaseBytes + kBytesPerInputPixel * input_pixels + per_processing_pixel * processing_pixels);
}

double estimateCpuSolveSeconds(int width, int height, const Config& config) {
  return kCpuSecondsPerProcessingPixel * processingSize(width, height, config.processing_level).pixels();
}

std::uint64_t parseMemAvailable(const std::string& meminfo) {
  std::istringstream lines(meminfo);
  std::string line;
  while (std::getline(lines, line)) {
    unsigned long long kib = 0;
    if (std::sscanf(line.c_str(), "MemAvailable: %llu kB", &kib) == 1) return std::uint64_t(kib) * 1024;
  }
  return 0;
}

std::uint64_t availableMemoryBytes() {
  std::ifstream file("/proc/meminfo");
  std::stringstream text;
  text << file.rdbuf();
  return parseMemAvailable(text.str());
}

std::string formatBytes(std::uint64_t bytes) {
  char buffer[32];
  if (bytes < 1000000000ull)
    std::snprintf(buffer, sizeof(buffer), "%.0f MB", double(bytes) / 1e6);
  else
    std::snprintf(buffer, sizeof(buffer), "%.1f GB", double(bytes) / 1e9);
  return buffer;
}

SizeCheck checkRunSize(int width, int height, const Config& config, bool cpu, std::uint64_t available_bytes) {
  SizeCheck check;
  const int level = config.processing_level;
  const ProcessingSize processing = processingSize(width, height, level);
  const std::string what = "a " + imageSizeText(width, height) + " pair at processing level " + std::to_string(level) +
                           " (" + imageSizeText(processing.width, processing.height) + ")";

  if (available_bytes > 0) {
    const std::uint64_t needed = estimateRunBytes(width, height, config);
    if (needed > available_bytes) {
      check.error = what + " needs about " + formatBytes(needed) + " of memory, but only " +
                    formatBytes(available_bytes) + " is available (MemAvailable in /proc/meminfo)";
      int fitting = -1;
      for (int l = level + 1; l <= kMaxSuggestedLevel && fitting < 0; ++l)
        if (estimateRunBytes(width, height, atLevel(config, l)) <= available_bytes) fitting = l;
      if (fitting >= 0) {
        const ProcessingSize s = processingSize(width, height, fitting);
        check.error += "; --processing-level " + std::to_string(fitting) + " solves at " +
                       imageSizeText(s.width, s.height) + " in about " +
                       formatBytes(estimateRunBytes(width, height, atLevel(config, fitting)));
      } else {
        check.error += "; even a coarser --processing-level does not fit: downscale the images first";
      }
      return check;
    }
  }

  if (cpu && processing.pixels() > kSlowProcessingPixels) {
    int suggested = level;
    while (suggested < kMaxSuggestedLevel && processingSize(width, height, suggested).pixels() > kSlowProcessingPixels)
      ++suggested;
    const ProcessingSize s = processingSize(width, height, suggested);
    check.warning = what + " is slow on the CPU: expect about " +
                    durationText(estimateCpuSolveSeconds(width, height, config)) +
                    " on 2 cores (less with more cores or the CUDA backend); --processing-level " +
                    std::to_string(suggested) + " solves at " + imageSizeText(s.width, s.height) + " in about " +
                    durationText(estimateCpuSolveSeconds(width, height, atLevel(config, suggested))) +
                    " and still writes every output at the input resolution";
  }
  return check;
}

}  // namespace io
}  // namespace mc_flow
