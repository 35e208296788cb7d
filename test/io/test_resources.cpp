// The size check of `mcflow run` (io/resources.h): memory estimate against measured peaks, /proc/meminfo
// parsing, and the warning and refusal texts, without allocating a large image.
#include <gtest/gtest.h>

#include <string>

#include "mc_flow/core/config.h"
#include "mc_flow/io/resources.h"

using namespace mc_flow;

namespace {

Config withLevelAndLabels(int level, int labels) {
  Config c;
  c.processing_level = level;
  c.initial_labels = labels;
  return c;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

}  // namespace

TEST(Resources, ProcessingSizeHalvesRoundingUp) {
  EXPECT_EQ(io::processingSize(8000, 6000, 0).width, 8000);
  EXPECT_EQ(io::processingSize(8000, 6000, 2).width, 2000);
  EXPECT_EQ(io::processingSize(8000, 6000, 2).height, 1500);
  EXPECT_EQ(io::processingSize(5, 3, 1).width, 3);
  EXPECT_EQ(io::processingSize(5, 3, 1).height, 2);
}

// Peak RSS of `mcflow run --backend cpu` on `mcflow synth` pairs, measured with /usr/bin/time -v.
TEST(Resources, EstimateIsWithinTenPercentOfMeasuredPeaks) {
  struct Measured {
    int width, height, level, labels;
    double megabytes;
  };
  for (const Measured& m :
       {Measured{640, 480, 0, 20, 181}, Measured{640, 480, 1, 20, 130}, Measured{1280, 960, 0, 20, 538},
        Measured{1280, 960, 1, 20, 351}, Measured{1280, 960, 0, 5, 469}, Measured{1280, 960, 1, 5, 324},
        Measured{2560, 1920, 0, 20, 1982}}) {
    const double estimate =
        double(io::estimateRunBytes(m.width, m.height, withLevelAndLabels(m.level, m.labels))) / 1e6;
    EXPECT_NEAR(estimate, m.megabytes, 0.1 * m.megabytes)
        << m.width << "x" << m.height << " level " << m.level << ", " << m.labels << " labels";
  }
}

TEST(Resources, CoarserLevelsNeedLessMemoryAndTime) {
  for (int level = 0; level < 4; ++level) {
    EXPECT_GT(io::estimateRunBytes(8000, 6000, withLevelAndLabels(level, 20)),
              io::estimateRunBytes(8000, 6000, withLevelAndLabels(level + 1, 20)));
    EXPECT_GT(io::estimateCpuSolveSeconds(8000, 6000, withLevelAndLabels(level, 20)),
              io::estimateCpuSolveSeconds(8000, 6000, withLevelAndLabels(level + 1, 20)));
  }
}

TEST(Resources, MemAvailableFromProcMeminfo) {
  EXPECT_EQ(io::parseMemAvailable("MemTotal:       24000000 kB\nMemFree:        20000000 kB\n"
                                  "MemAvailable:   23831444 kB\nBuffers:          100 kB\n"),
            23831444ull * 1024);
  EXPECT_EQ(io::parseMemAvailable("MemTotal: 1 kB\n"), 0u);  // an old kernel without the line: unknown
  EXPECT_EQ(io::parseMemAvailable(""), 0u);
  EXPECT_GT(io::availableMemoryBytes(), 0u) << "this machine's /proc/meminfo has no MemAvailable";
}

TEST(Resources, SmallPairsPassWithoutAWord) {
  const io::SizeCheck check = io::checkRunSize(640, 480, Config(), true, 8000000000ull);
  EXPECT_EQ(check.warning, "");
  EXPECT_EQ(check.error, "");
}

TEST(Resources, LargePairOnTheCpuWarnsWithTheTimeAndACoarserLevel) {
  const io::SizeCheck check = io::checkRunSize(8000, 6000, Config(), true, 64000000000ull);
  EXPECT_EQ(check.error, "");
  EXPECT_TRUE(contains(check.warning, "a 8000x6000 pair at processing level 0 (8000x6000) is slow on the CPU"))
      << check.warning;
  EXPECT_TRUE(contains(check.warning, " min on 2 cores")) << check.warning;
  // Level 3 (1000x750) is the first at or below the slowness threshold.
  EXPECT_TRUE(contains(check.warning, "--processing-level 3 solves at 1000x750")) << check.warning;
  // The CUDA backend: no slowness warning (the memory check still applies).
  EXPECT_EQ(io::checkRunSize(8000, 6000, Config(), false, 64000000000ull).warning, "");
  // Unknown available memory: no refusal.
  EXPECT_EQ(io::checkRunSize(8000, 6000, Config(), true, 0).error, "");
}

TEST(Resources, PairThatDoesNotFitIsRefusedNamingBothAmountsAndALevelThatFits) {
  const std::uint64_t available = 12000000000ull;  // 12 GB
  const io::SizeCheck check = io::checkRunSize(8000, 6000, Config(), true, available);
  const std::string needed = io::formatBytes(io::estimateRunBytes(8000, 6000, Config()));
  EXPECT_TRUE(contains(check.error, "a 8000x6000 pair at processing level 0 (8000x6000) needs about " + needed +
                                        " of memory, but only 12.0 GB is available"))
      << check.error;
  int fits = 1;
  while (io::estimateRunBytes(8000, 6000, withLevelAndLabels(fits, 20)) > available) ++fits;
  EXPECT_TRUE(contains(check.error, "--processing-level " + std::to_string(fits) + " solves at")) << check.error;

  // The full-resolution images alone exceed 2 GB: no level helps.
  const io::SizeCheck hopeless = io::checkRunSize(8000, 6000, Config(), true, 2000000000ull);
  EXPECT_TRUE(contains(hopeless.error, "downscale the images first")) << hopeless.error;
}

TEST(Resources, BytesAreWrittenForPeople) {
  EXPECT_EQ(io::formatBytes(540000000ull), "540 MB");
  EXPECT_EQ(io::formatBytes(18700000000ull), "18.7 GB");
}
