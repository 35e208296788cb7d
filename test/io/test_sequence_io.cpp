// Sequences on disk: TUM lists and associations, numbered frame folders, trajectories.csv.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "temp_dir.h"
#include "mc_flow/core/error.h"
#include "mc_flow/io/sequence_io.h"

namespace fs = std::filesystem;
using namespace mc_flow;

namespace {

void write(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

TEST(SequenceIo, TumListsAreMatchedByNearestStamp) {
  const test::TempDir dir("mcflow_tum_");
  write(dir.path() / "rgb.txt", "# colour\n1.000 rgb/a.png\n1.033 rgb/b.png\n1.500 rgb/c.png\n");
  write(dir.path() / "depth.txt", "# depth\n1.010 depth/a.png\n1.040 depth/b.png\n1.600 depth/c.png\n");
  const auto frames = io::listTumSequence(dir.path().string());
  ASSERT_EQ(frames.size(), 2u) << "1.5 has no depth within 0.02 s";
  EXPECT_DOUBLE_EQ(frames[0].stamp, 1.0);
  EXPECT_EQ(fs::path(frames[0].depth).filename(), "a.png");
  EXPECT_EQ(fs::path(frames[1].rgb).filename(), "b.png");
  EXPECT_EQ(fs::path(frames[1].depth).filename(), "b.png");
}

TEST(SequenceIo, AssociationsWinAndBadLinesAreNamed) {
  const test::TempDir dir("mcflow_tum_");
  write(dir.path() / "rgb.txt", "1 rgb/x.png\n");
  write(dir.path() / "depth.txt", "1 depth/x.png\n");
  write(dir.path() / "associations.txt", "2.0 rgb/p.png 2.01 depth/q.png\n3.0 rgb/r.png 3.0 depth/s.png\n");
  const auto frames = io::listTumSequence(dir.path().string());
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(fs::path(frames[0].depth).filename(), "q.png");
  write(dir.path() / "associations.txt", "2.0 rgb/p.png\n");
  try {
    io::listTumSequence(dir.path().string());
    FAIL() << "a short line was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 1"), std::string::npos) << e.what();
  }
  EXPECT_THROW(io::listTumSequence((dir.path() / "absent").string()), InputError);
}

TEST(SequenceIo, NumberedFramesPairInNameOrder) {
  const test::TempDir dir("mcflow_frames_");
  for (const char* n : {"0002.png", "0001.png"}) {
    write(dir.path() / "rgb" / n, "");
    write(dir.path() / "depth" / n, "");
  }
  const auto frames = io::listNumberedFrames(dir.path().string(), 10.0);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(fs::path(frames[0].rgb).filename(), "0001.png");
  EXPECT_DOUBLE_EQ(frames[1].stamp, 0.1);
  write(dir.path() / "depth" / "0003.png", "");
  EXPECT_THROW(io::listNumberedFrames(dir.path().string(), 10.0), InputError);
  EXPECT_THROW(io::listNumberedFrames(dir.path().string(), 0.0), InputError);
}

TEST(SequenceIo, TrajectoryRowsHoldEverySegment) {
  Result r;
  Segment a, b;
  a.id = 3;
  b.id = 8;
  b.twist << 0.01, 0, 0, 0, 0, 0.02;
  b.support = 12;
  r.segments = {a, b};
  const std::string rows = io::trajectoryCsvRows(4, 1.5, r);
  EXPECT_EQ(std::count(rows.begin(), rows.end(), '\n'), 2);
  EXPECT_NE(rows.find("4,1.5"), std::string::npos) << rows;
  EXPECT_NE(rows.find(",8,0.01,0,0,0,0,0.02,12\n"), std::string::npos) << rows;
  const cv::Mat picture = io::idsOverTimeImage({{{3, 10.0}}, {{3, 10.0}, {8, 12.0}}});
  EXPECT_EQ(picture.cols, 2 * 8);
  EXPECT_EQ(picture.rows, 2 * 8);
}

}  // namespace
