/**
 * @file simplex_projection.h
 * @brief Euclidean projection onto the probability simplex, shared by the CPU and CUDA label steps so that
 * both compute bit-identical results (only additions, comparisons and one division: no FMA contraction).
 */
#pragma once

#include "mc_flow/core/host_device.h"

namespace mc_flow {

/// @brief Projects v[0], v[stride], ..., v[(n-1) stride] onto {u >= 0, sum u = 1} in place.
///
/// Michelot's active-set algorithm: theta = (sum of the active values - 1) / |active|, values at or below
/// theta drop out, repeat until theta stops rising; u = max(v - theta, 0). Any lower bound of the final theta
/// is a valid start: (sum - 1)/n is one, and so is max - 1, which is almost exact for the usual nearly
/// one-hot pixel, so the loop ends after one or two passes. Sums run over four interleaved accumulators
/// (a single chain of dependent double additions was the bottleneck of the CPU label step); inactive
/// values add 0.0, which leaves a sum unchanged, so the loop has no data-dependent branch.
MCFLOW_HOST_DEVICE inline void projectOntoSimplexStrided(float* v, int n, int stride) {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0, largest = -1e300;
  int j = 0;
  for (; j + 3 < n; j += 4) {
    const double a = v[j * stride], b = v[(j + 1) * stride], c = v[(j + 2) * stride], d = v[(j + 3) * stride];
    s0 += a;
    s1 += b;
    s2 += c;
    s3 += d;
    const double ab = a > b ? a : b, cd = c > d ? c : d, m = ab > cd ? ab : cd;
    largest = m > largest ? m : largest;
  }
  for (; j < n; ++j) {
    const double a = v[j * stride];
    s0 += a;
    largest = a > largest ? a : largest;
  }
  const double by_mean = ((s0 + s1) + (s2 + s3) - 1.0) / n, by_max = largest - 1.0;
  double theta = by_mean > by_max ? by_mean : by_max;
  for (int pass = 0; pass < n; ++pass) {
    double a0 = 0, a1 = 0, a2 = 0, a3 = 0;
    int active = 0;
    int k = 0;
    for (; k + 3 < n; k += 4) {
      const double a = v[k * stride], b = v[(k + 1) * stride], c = v[(k + 2) * stride], d = v[(k + 3) * stride];
      a0 += a > theta ? a : 0.0;
      a1 += b > theta ? b : 0.0;
      a2 += c > theta ? c : 0.0;
      a3 += d > theta ? d : 0.0;
      active += int(a > theta) + int(b > theta) + int(c > theta) + int(d > theta);
    }
    for (; k < n; ++k) {
      const double a = v[k * stride];
      a0 += a > theta ? a : 0.0;
      active += int(a > theta);
    }
    const double next = ((a0 + a1) + (a2 + a3) - 1.0) / active;
    if (!(next > theta)) break;  // theta only rises; no rise means the active set is final
    theta = next;
  }
  const float t = float(theta);
  for (int i = 0; i < n; ++i) {
    const float u = v[i * stride] - t;
    v[i * stride] = u > 0.f ? u : 0.f;
  }
}

}  // namespace mc_flow
