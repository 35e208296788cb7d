#include "mc_flow/testing/soak.h"

#include <algorithm>
#include <fstream>
#include <sstream>

#include "mc_flow/testing/bench.h"

namespace mc_flow {

double processStatusBytes(const std::string& field) {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.compare(0, field.size() + 1, field + ":") != 0) continue;
    std::istringstream values(line.substr(field.size() + 1));
    double kb = -1;
    std::string unit;
    if (values >> kb >> unit && unit == "kB") return kb * 1024.0;
    return -1;
  }
  return -1;
}

FlatnessVerdict judgeFlatness(const std::vector<MemorySample>& samples, long warmup_solves, double tolerance_bytes) {
  FlatnessVerdict v;
  std::vector<MemorySample> judged;
  for (const MemorySample& s : samples)
    if (s.solves >= warmup_solves) judged.push_back(s);
  if (judged.size() < 2) return v;
  v.judged = true;
  v.first_solves = judged.front().solves;
  v.last_solves = judged.back().solves;
  const std::size_t third = std::max<std::size_t>(1, judged.size() / 3);
  std::vector<double> first, last;
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  v.peak = judged.front().bytes;
  for (std::size_t i = 0; i < judged.size(); ++i) {
    const MemorySample& s = judged[i];
    if (i < third) first.push_back(s.bytes);
    if (i >= judged.size() - third) last.push_back(s.bytes);
    v.peak = std::max(v.peak, s.bytes);
    const double x = double(s.solves - v.first_solves), y = s.bytes - judged.front().bytes;
    n += 1;
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  v.baseline = median(first);
  v.end = median(last);
  v.growth = v.end - v.baseline;
  const double denominator = n * sxx - sx * sx;
  v.slope_per_1000 = denominator > 0 ? 1000.0 * (n * sxy - sx * sy) / denominator : 0.0;
  v.flat = v.growth <= tolerance_bytes;
  return v;
}

}  // namespace mc_flow
