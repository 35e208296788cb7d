/**
 * @file nearest_centre.h
 * @brief K-means' per-point rules (the nearest centre, the squared distance of the seeding and of a centre's shift),
 * written once for the host (kmeans.cpp) and the CUDA backend's K-means and assignment (cuda/kmeans.cu), with every
 * float operation rounded on its own so both give the same bits.
 */
#pragma once

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/rounded.h"

namespace mc_flow {

/// @brief Index of the centre nearest to the point (x, y, z) by squared Euclidean distance; `centres` holds
/// `count` >= 1 centres as x, y, z triples. The lowest index wins a tie.
MCFLOW_HOST_DEVICE inline int nearestCentreIndex(float x, float y, float z, const float* centres, int count) {
  int best = 0;
  float best_distance = 0.f;
  for (int c = 0; c < count; ++c) {
    const float dx = subRn(x, centres[3 * c]), dy = subRn(y, centres[3 * c + 1]), dz = subRn(z, centres[3 * c + 2]);
    const float distance = addRn(addRn(mulRn(dx, dx), mulRn(dy, dy)), mulRn(dz, dz));
    if (c == 0 || distance < best_distance) {
      best_distance = distance;
      best = c;
    }
  }
  return best;
}

/// @brief |p - c|^2 for the k-means++ seeding's distances and a centre's shift, in the order of Eigen's
/// (p - c).squaredNorm() of a 3-vector, x^2 + (y^2 + z^2), which the host's K-means used before this was shared.
MCFLOW_HOST_DEVICE inline float kmeansSquaredDistance(float x, float y, float z, const float* centre) {
  const float dx = subRn(x, centre[0]), dy = subRn(y, centre[1]), dz = subRn(z, centre[2]);
  return addRn(mulRn(dx, dx), addRn(mulRn(dy, dy), mulRn(dz, dz)));
}

}  // namespace mc_flow
