// What the benchmark tools share besides their command line (mc_flow/testing/bench.h); the command line itself:
// test_command_line.cpp.
#include <gtest/gtest.h>

#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/testing/bench.h"

namespace mc_flow {
namespace {

TEST(BenchMedian, MiddleElementOfTheSortedValues) {
  EXPECT_EQ(median({}), 0.0);
  EXPECT_EQ(median({3.0}), 3.0);
  EXPECT_EQ(median({5.0, 1.0, 3.0}), 3.0);
  EXPECT_EQ(median({4.0, 1.0, 3.0, 2.0}), 3.0) << "even count: the upper of the two middle values";
}

TEST(BenchRegularizers, BothOrOneByName) {
  EXPECT_EQ(regularizerChoice("both"), (std::vector<Regularizer>{Regularizer::Quadratic, Regularizer::TotalVariation}));
  EXPECT_EQ(regularizerChoice("tv"), (std::vector<Regularizer>{Regularizer::TotalVariation}));
  EXPECT_THROW(regularizerChoice("huber"), ConfigError);
}

}  // namespace
}  // namespace mc_flow
