// The soak benchmark's measurements and its flatness rule (mc_flow/testing/soak.h).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include "mc_flow/testing/soak.h"

namespace mc_flow {
namespace {

constexpr double kMiB = 1024.0 * 1024.0;

TEST(Soak, ResidentSetSizeFollowsTouchedMemory) {
  const double before = processStatusBytes("VmRSS");
  ASSERT_GT(before, 0) << "VmRSS of /proc/self/status";
  const std::size_t size = std::size_t(64 * kMiB);
  std::unique_ptr<char[]> block(new char[size]);
  std::memset(block.get(), 1, size);  // resident only once written
  const double after = processStatusBytes("VmRSS");
  EXPECT_GT(after - before, 48 * kMiB) << "before " << before / kMiB << " MiB, after " << after / kMiB << " MiB";
  EXPECT_EQ(block[size - 1], 1);
  EXPECT_GE(processStatusBytes("VmHWM"), after);
  EXPECT_EQ(processStatusBytes("NoSuchField"), -1);
}

std::vector<MemorySample> series(int count, long every, double (*bytes)(long solves)) {
  std::vector<MemorySample> out;
  for (int i = 1; i <= count; ++i) out.push_back({i * every, bytes(i * every)});
  return out;
}

TEST(Soak, GrowthDuringTheWarmUpAndSinglePeaksAreNotJudgedASteadyLeakIs) {
  // 200 MiB reached at solve 3000, then +-1 MiB of allocator noise and one peak of +20 MiB: flat.
  const auto warm_then_flat = series(20, 500, [](long s) {
    if (s <= 3000) return 200 * kMiB * double(s) / 3000.0;
    return 200 * kMiB + (s == 6000 ? 20 * kMiB : (s / 500) % 2 ? kMiB : -kMiB);
  });
  const FlatnessVerdict flat = judgeFlatness(warm_then_flat, 3000, 4 * kMiB);
  ASSERT_TRUE(flat.judged);
  EXPECT_TRUE(flat.flat) << "growth " << flat.growth / kMiB << " MiB";
  EXPECT_EQ(flat.first_solves, 3000);
  EXPECT_EQ(flat.last_solves, 10000);
  EXPECT_DOUBLE_EQ(flat.peak, 220 * kMiB);
  EXPECT_LE(std::abs(flat.growth), 2 * kMiB);
  // The same series judged from solve 0: the warm-up's growth (a third of the samples) counts.
  EXPECT_FALSE(judgeFlatness(warm_then_flat, 0, 4 * kMiB).flat);

  // A leak of 1 KiB per solve: the last third's median is 6500 solves after the first third's (upper medians of
  // 6 samples: solves 2500 and 9000), and the trend is 1000 KiB per 1000 solves.
  const auto leak = series(20, 500, [](long s) { return 100 * kMiB + 1024.0 * double(s); });
  const FlatnessVerdict leaking = judgeFlatness(leak, 1000, 4 * kMiB);
  ASSERT_TRUE(leaking.judged);
  EXPECT_FALSE(leaking.flat);
  EXPECT_NEAR(leaking.growth, 6500 * 1024.0, 1.0);
  EXPECT_NEAR(leaking.slope_per_1000, 1000 * 1024.0, 1e-3);
  EXPECT_TRUE(judgeFlatness(leak, 1000, 8 * kMiB).flat) << "within a large enough tolerance";
}

TEST(Soak, NoVerdictWithoutTwoSamplesAfterTheWarmUp) {
  const auto short_run = series(4, 100, [](long) { return kMiB; });
  EXPECT_FALSE(judgeFlatness(short_run, 400, kMiB).judged);
  EXPECT_FALSE(judgeFlatness(short_run, 401, kMiB).judged);
  EXPECT_TRUE(judgeFlatness(short_run, 300, kMiB).judged);
  EXPECT_FALSE(judgeFlatness({}, 0, kMiB).judged);
}

}  // namespace
}  // namespace mc_flow
