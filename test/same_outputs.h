// Bit-for-bit comparison of two solves' output images (NaN where depth is invalid compares equal to itself), shared
// by the CPU and CUDA tests of Solver::recycle.
#pragma once

#include <gtest/gtest.h>

#include <cstring>
#include <vector>

#include "mc_flow/core/solver.h"

namespace mc_flow {
namespace test {

template <typename T>
bool sameBits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

inline void expectSameOutputImages(const Result& actual, const Result& expected) {
  EXPECT_TRUE(sameBits(actual.scene_flow.data, expected.scene_flow.data)) << "scene_flow";
  EXPECT_TRUE(sameBits(actual.optical_flow.data, expected.optical_flow.data)) << "optical_flow";
  EXPECT_TRUE(sameBits(actual.moved_depth.data, expected.moved_depth.data)) << "moved_depth";
  EXPECT_TRUE(sameBits(actual.soft_labels.data, expected.soft_labels.data)) << "soft_labels";
  EXPECT_TRUE(sameBits(actual.labels.data, expected.labels.data)) << "labels";
  EXPECT_TRUE(sameBits(actual.occlusion.data, expected.occlusion.data)) << "occlusion";
  EXPECT_EQ(actual.scene_flow.width, expected.scene_flow.width);
  EXPECT_EQ(actual.soft_labels.count, expected.soft_labels.count);
}

}  // namespace test
}  // namespace mc_flow
