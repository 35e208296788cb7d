// Sequences on disk: TUM lists and associations, numbered frame folders, trajectories.csv.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>

#include <Eigen/Geometry>

#include "temp_dir.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/sequence_folder.h"
#include "mc_flow/io/sequence_io.h"
#include "mc_flow/io/trajectory_eval.h"

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
  EXPECT_NE(rows.find(",8,0.01,0,0,0,0,0.02,12,,,,,,,,\n"), std::string::npos) << rows;  // no world: empty columns
  // With the world: segment 8 is the world, segment 3 moves at 0.5 m/s along x.
  r.world.ids = {8};
  std::vector<WorldVelocity> world(2);
  world[0].moving = true;
  world[0].linear = Eigen::Vector3d(0.5, 0, 0);
  const std::string with_world = io::trajectoryCsvRows(4, 1.5, r, &world);
  EXPECT_NE(with_world.find(",3,0,0,0,0,0,0,0,0,1,0.5,0,0,0,0,0\n"), std::string::npos) << with_world;
  EXPECT_NE(with_world.find(",12,1,0,0,0,0,0,0,0\n"), std::string::npos) << with_world;
  world.pop_back();
  EXPECT_THROW(io::trajectoryCsvRows(4, 1.5, r, &world), InputError);
  const cv::Mat picture = io::idsOverTimeImage({{{3, 10.0}}, {{3, 10.0}, {8, 12.0}}});
  EXPECT_EQ(picture.cols, 2 * 8);
  EXPECT_EQ(picture.rows, 2 * 8);
}

TEST(SequenceIo, TumTrajectoriesRoundTripAndBadLinesNameTheirLine) {
  const test::TempDir dir("mcflow_traj_io_");
  Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();
  pose.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  pose.topRightCorner<3, 1>() = Eigen::Vector3d(0.1, -0.2, 1.5);
  const fs::path file = dir.path() / "trajectory.txt";
  write(file, "# a comment\n\n" + io::tumTrajectoryLine(12.5, Eigen::Matrix4d::Identity()) +
                  io::tumTrajectoryLine(12.6, pose));
  const auto poses = io::readTumTrajectory(file.string());
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_DOUBLE_EQ(poses[0].first, 12.5);
  EXPECT_TRUE(poses[1].second.isApprox(pose, 1e-5)) << poses[1].second;
  write(file, io::tumTrajectoryLine(1.0, pose) + "2.0 0 0 0 0 0 0\n");
  try {
    io::readTumTrajectory(file.string());
    FAIL() << "a line of 7 numbers was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos) << e.what();
  }
  write(file, "1.0 0 0 0 0 0 0 2\n");  // a quaternion of norm 2
  EXPECT_THROW(io::readTumTrajectory(file.string()), InputError);
  EXPECT_THROW(io::readTumTrajectory((dir.path() / "missing.txt").string()), InputError);
}

TEST(SequenceIo, ATrajectoryThatIsTheTruthMovedRigidlyHasNoErrorAndANoisyOneHas) {
  io::StampedPoses truth, moved;
  const Eigen::Matrix4d frame = [] {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    m.topRightCorner<3, 1>() = Eigen::Vector3d(1, 2, 3);
    return m;
  }();
  for (int i = 0; i < 90; ++i) {  // 3 s at 30 Hz along a curve
    Eigen::Matrix4d p = Eigen::Matrix4d::Identity();
    p.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.01 * i, Eigen::Vector3d::UnitY()).toRotationMatrix();
    p.topRightCorner<3, 1>() = Eigen::Vector3d(0.01 * i, 0.002 * i * i / 30.0, 0.005 * i);
    truth.emplace_back(100.0 + i / 30.0, p);
    moved.emplace_back(100.0 + i / 30.0 + 0.005, frame * p);  // another frame, stamps 5 ms late
  }
  const io::TrajectoryErrors exact = io::evaluateTrajectory(truth, moved, 0.02, -0.005);
  EXPECT_EQ(exact.matched, 90);
  EXPECT_LT(exact.ate_rmse_m, 1e-9);
  EXPECT_LT(exact.rpe_frame_trans_m, 1e-9);
  EXPECT_LT(exact.rpe_frame_rot_deg, 1e-5);
  EXPECT_EQ(exact.rpe_frame_pairs, 89);
  EXPECT_GT(exact.rpe_second_pairs, 0);
  // One pose 3 cm off: the frame-to-frame RPE sees it twice, the ATE about 3 cm / sqrt(90) after the alignment.
  moved[45].second(0, 3) += 0.03;
  const io::TrajectoryErrors noisy = io::evaluateTrajectory(truth, moved, 0.02, -0.005);
  EXPECT_NEAR(noisy.rpe_frame_trans_m, std::sqrt(2 * 0.03 * 0.03 / 89), 1e-3);
  EXPECT_GT(noisy.ate_rmse_m, 0.002);
  EXPECT_LT(noisy.ate_rmse_m, 0.004);
  // Stamps that do not match: an error naming the counts.
  try {
    io::evaluateTrajectory(truth, moved, 0.02, 50.0);
    FAIL() << "no match was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("0 of 90"), std::string::npos) << e.what();
  }
  const cv::Mat plot = io::trajectoryPlot(noisy, 200);
  EXPECT_EQ(plot.rows, 200);
}

TEST(SequenceIo, TheMovingMaskHoldsThePixelsOfMovingSegments) {
  Result r;
  Segment a, b;
  a.id = 3;
  b.id = 8;
  r.segments = {a, b};
  r.labels = ImageI32(3, 1, 1, 0);
  r.labels.data = {3, 8, 0};
  std::vector<WorldVelocity> world(2);
  world[1].moving = true;
  const ImageU8 mask = movingMask(r, world);
  EXPECT_EQ(mask.data, (std::vector<std::uint8_t>{0, 255, 0}));
  // Ids that are no segment's (negative, beyond the largest, 0) are not moving; a moving segment's id anywhere.
  r.labels = ImageI32(6, 1, 1, 0);
  r.labels.data = {-1, 8, 9, 1000, 3, 8};
  world[0].moving = true;
  EXPECT_EQ(movingMask(r, world).data, (std::vector<std::uint8_t>{0, 255, 0, 0, 255, 255}));
  world.pop_back();
  EXPECT_THROW(movingMask(r, world), InputError);
}

}  // namespace

TEST(SequenceIo, OdometryCsvRoundTripsAndNamesABadLine) {
  const test::TempDir dir("mcflow_odometry_io_");
  OdometryStep step;
  step.first = 1305031229.528748;
  step.second = 1305031229.564425;
  step.twist << 0.0123, -0.004, 0.0007, -0.009, 0.067, 0.0086;
  Matrix6d a;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) a(r, c) = std::sin(1.0 + 7 * r + c);  // any full matrix: a a^T is symmetric
  step.covariance = 1e-6 * (a * a.transpose()) + 1.6e-5 * Matrix6d::Identity();
  const fs::path file = dir.path() / "odometry.csv";
  write(file, io::odometryCsvHeader() + io::odometryCsvRow(0, step) + io::odometryCsvRow(1, step));
  const std::vector<OdometryStep> read = io::readOdometryCsv(file.string());
  ASSERT_EQ(read.size(), 2u);
  EXPECT_NEAR(read[1].first, step.first, 1e-6);
  EXPECT_NEAR(read[1].second, step.second, 1e-6);
  EXPECT_TRUE(read[1].twist.isApprox(step.twist, 1e-8)) << read[1].twist.transpose();
  EXPECT_TRUE(read[1].covariance.isApprox(step.covariance, 1e-10)) << read[1].covariance;
  EXPECT_EQ(read[1].covariance, read[1].covariance.transpose());
  write(file, io::odometryCsvHeader() + io::odometryCsvRow(0, step) + "1,2,3\n");
  try {
    io::readOdometryCsv(file.string());
    FAIL() << "a line of 3 numbers was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 3"), std::string::npos) << e.what();
  }
  EXPECT_THROW(io::readOdometryCsv((dir.path() / "missing.csv").string()), InputError);
}

// A sequence folder (mcflow export-seq) reads back what was written, and a malformed one is named.
TEST(SequenceFolder, FramesStampsAndIntrinsicsReadBackAndBadFilesAreNamed) {
  const test::TempDir dir("mcflow_sequence_folder_");
  const std::string folder = (dir.path() / "seq").string();
  RgbdFrame frame;
  frame.intensity = ImageF(5, 4, 1, 0.25f);
  frame.depth = ImageF(5, 4, 1, 1.5f);
  frame.depth.data[3] = NAN;
  writeSequenceFrame(folder, 0, frame);
  frame.intensity.data[7] = 0.75f;
  writeSequenceFrame(folder, 1, frame);
  const Intrinsics K{300.25, 301.5, 2.0, 1.5};
  writeSequenceIndex(folder, K, {10.0, 10.0333333333333333});
  const SequenceFolder read = readSequenceFolder(folder);
  EXPECT_EQ(read.K.fx, K.fx);
  EXPECT_EQ(read.K.cy, K.cy);
  ASSERT_EQ(read.stamps.size(), 2u);
  EXPECT_EQ(read.stamps[1], 10.0333333333333333);
  const RgbdFrame second = read.frame(1);
  EXPECT_EQ(second.intensity.data, frame.intensity.data);
  EXPECT_TRUE(std::isnan(second.depth.data[3]));
  EXPECT_EQ(second.depth.data[4], 1.5f);

  auto throwsNaming = [](const std::function<void()>& call, const std::string& part) {
    try {
      call();
      ADD_FAILURE() << "no error, expected one naming " << part;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  throwsNaming([&] { read.frame(2); }, "frame index 2 is past the last frame (2 frames");
  fs::remove(fs::path(folder) / "depth_00001.pfm");
  throwsNaming([&] { read.frame(1); }, "depth_00001.pfm");
  write(fs::path(folder) / "stamps.txt", "10.0\nten\n");
  throwsNaming([&] { readSequenceFolder(folder); }, "stamps.txt:2");
  write(fs::path(folder) / "stamps.txt", "10.0\n10.1 x\n");
  throwsNaming([&] { readSequenceFolder(folder); }, "stamps.txt:2");
  write(fs::path(folder) / "stamps.txt", "10.0\n");
  throwsNaming([&] { readSequenceFolder(folder); }, "1 frame(s)");
  write(fs::path(folder) / "intrinsics.txt", "0 300 2 1.5\n");
  throwsNaming([&] { readSequenceFolder(folder); }, "intrinsics.txt");
  fs::remove(fs::path(folder) / "intrinsics.txt");
  throwsNaming([&] { readSequenceFolder(folder); }, "intrinsics.txt: cannot be opened");
}
