/**
 * @file nearest_centre.h
 * @brief K-means' nearest-centre rule, written once for the host (kmeans.cpp) and the CUDA backend's assignment
 * of the label level (cuda/kmeans.cu), with every float operation rounded on its own so both give the same labels.
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

}  // namespace mc_flow
