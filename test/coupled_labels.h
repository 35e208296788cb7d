// Soft labels whose blends couple some motion labels strongly and some weakly, for the tests of the motion step's
// grouping (test_core and test_cuda).
#pragma once

#include "mc_flow/core/soft_labels.h"

namespace mc_flow {
namespace test {

/// Four motion labels in vertical strips: labels 0-1 and 1-2 blend half and half on wide strips (strong couplings),
/// 0 and 2 share every eighth row of label 0's strip at 0.95 / 0.05 (weak, but inside the group {0, 1, 2}), 2 and 3
/// share every eighth row of label 3's strip the same way (weak: label 3's only coupling).
inline SoftLabels labelsWithWeakAndStrongCouplings(int width, int height) {
  SoftLabels u(width, height, 5, 0.f);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const bool weak = y % 8 == 0;
      if (x < width / 5) {
        u.at(0, x, y) = weak ? 0.95f : 1.f;
        u.at(2, x, y) = weak ? 0.05f : 0.f;
      } else if (x < width / 2) {
        u.at(0, x, y) = 0.5f;
        u.at(1, x, y) = 0.5f;
      } else if (x < 7 * width / 10) {
        u.at(1, x, y) = 0.5f;
        u.at(2, x, y) = 0.5f;
      } else {
        u.at(3, x, y) = weak ? 0.95f : 1.f;
        u.at(2, x, y) = weak ? 0.05f : 0.f;
      }
    }
  return u;
}

}  // namespace test
}  // namespace mc_flow
