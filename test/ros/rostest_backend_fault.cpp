// A GPU fault in the middle of a stream, at the node level: backend_fault.test starts the nodelet in a test host
// with --fault 3 (nodelet_with_fault.cpp), so the pipeline's first backend throws a BackendError in its third solve (on
// this machine the wrapped backend is the CPU one; on the GPU machine it is the CUDA one). The nodelet must skip that
// pair with one warning that names the fault and says it continues on the CPU, count it in /diagnostics (warnings of
// kind "backend", the fallback count, the failure, the backend, a WARN summary), and solve every later pair.
#include <gtest/gtest.h>

#include <cstdio>

#include <diagnostic_msgs/DiagnosticArray.h>

#include "mc_flow/SegmentArray.h"
#include "rostest_common.h"

using mcflow_test::Collector;
using mcflow_test::diagnosticCount;
using mcflow_test::diagnosticValue;
using mcflow_test::RosoutWatcher;
using mcflow_test::SyntheticCamera;
using mcflow_test::waitFor;

namespace {

constexpr int kWidth = 160, kHeight = 120;  // processed as they are (automatic downsampling: factor 1)
constexpr int kFrames = 10;                 // pairs 1..9; the fault strikes in pair 2 or 3
const char* const kFaultText = "injected fault in stage labelStep of solve 3";

}  // namespace

class BackendFault : public ::testing::Test {
 protected:
  void SetUp() override {
    camera_ = std::make_unique<SyntheticCamera>(nh_, kWidth, kHeight);
    watcher_ = std::make_unique<RosoutWatcher>(nh_);
    segments_ = std::make_unique<Collector<mc_flow::SegmentArray>>(nh_, "/mc_flow/segments");
    diagnostics_ = std::make_unique<Collector<diagnostic_msgs::DiagnosticArray>>(nh_, "/diagnostics");
    ASSERT_TRUE(waitFor([this] { return camera_->inputSubscribers() >= 3; }, 60.0)) << "the nodelet never subscribed";
    ASSERT_TRUE(waitFor([this] { return diagnosticCount(*diagnostics_, "pairs solved") >= 0; }, 30.0))
        << "no diagnostics";
    ros::WallDuration(1.0).sleep();  // let the /rosout subscription connect too
  }

  const mc_flow::SegmentArray* solvedAt(const ros::Time& stamp) const {
    for (const auto& m : segments_->messages()) {
      if (m->header.stamp == stamp) return m.get();
    }
    return nullptr;
  }

  int rosoutLines(const std::string& text) const {
    int n = 0;
    for (const auto& m : watcher_->all()) n += m.find(text) != std::string::npos ? 1 : 0;
    return n;
  }

  std::string dump() const {
    std::string all;
    for (const auto& m : watcher_->all()) all += "\n  " + m;
    return all;
  }

  /// The last MC-Flow status seen on /diagnostics (null when none).
  const diagnostic_msgs::DiagnosticStatus* lastStatus(diagnostic_msgs::DiagnosticArrayConstPtr& keep) const {
    const auto all = diagnostics_->messages();
    for (auto it = all.rbegin(); it != all.rend(); ++it) {
      for (const auto& status : (*it)->status) {
        if (status.name.find("MC-Flow") == std::string::npos) continue;
        keep = *it;
        return &status;
      }
    }
    return nullptr;
  }

  ros::NodeHandle nh_;
  std::unique_ptr<SyntheticCamera> camera_;
  std::unique_ptr<RosoutWatcher> watcher_;
  std::unique_ptr<Collector<mc_flow::SegmentArray>> segments_;
  std::unique_ptr<Collector<diagnostic_msgs::DiagnosticArray>> diagnostics_;
};

TEST_F(BackendFault, AFaultMidStreamWarnsOnceAndTheStreamGoesOnOnTheCpu) {
  const ros::WallTime started = ros::WallTime::now();
  const ros::Time start(7000.0);
  const ros::Duration interval(0.1);
  // In lockstep: each frame is published once the previous one is done with, so none is dropped and every
  // frame after the first ends a pair that is either solved (~segments) or skipped by the fault (/rosout).
  int fault_frame = -1;
  camera_->publish(0, start);
  ros::WallDuration(0.5).sleep();  // the first frame starts the sequence: no output
  for (int t = 1; t < kFrames; ++t) {
    const ros::Time stamp = start + interval * t;
    const int faults_before = rosoutLines(kFaultText);
    camera_->publish(t % 10, stamp);
    const bool done = waitFor([&] { return solvedAt(stamp) || rosoutLines(kFaultText) > faults_before; }, 30.0);
    ASSERT_TRUE(done) << "frame " << t << ": neither a solved pair nor the fault's warning (the fault struck at frame "
                      << fault_frame << ")" << dump();
    if (!solvedAt(stamp)) {
      ASSERT_EQ(fault_frame, -1) << "frame " << t << ": a second pair failed" << dump();
      fault_frame = t;
    }
  }

  // The fault strikes in the third solve of the first backend: pair 3, or pair 2 when a warm pair was re-solved
  // cold (two solves). At least one pair was solved on that backend before it.
  ASSERT_GE(fault_frame, 2) << "no pair failed, or the first one did" << dump();
  ASSERT_LE(fault_frame, 3) << dump();
  for (int t = 1; t < kFrames; ++t) {
    const mc_flow::SegmentArray* m = solvedAt(start + interval * t);
    if (t == fault_frame) {
      EXPECT_EQ(m, nullptr) << "the failed pair was published";
      continue;
    }
    ASSERT_NE(m, nullptr) << "pair ending at frame " << t << " not solved (the fault struck at frame " << fault_frame
                          << ")";
    EXPECT_FALSE(m->segments.empty()) << "frame " << t;
    if (t > fault_frame) EXPECT_EQ(m->backend, "cpu") << "frame " << t;
  }
  EXPECT_GE(kFrames - 1 - fault_frame, 6) << "too few pairs after the fault to show that the stream goes on";

  // The diagnostics (1 Hz) catch up: every pair but the failed one solved, one frame skipped, one fallback.
  EXPECT_TRUE(waitFor([&] { return diagnosticCount(*diagnostics_, "pairs solved") >= kFrames - 2; }, 5.0))
      << "pairs solved: " << diagnosticValue(*diagnostics_, "pairs solved");
  EXPECT_EQ(diagnosticCount(*diagnostics_, "pairs solved"), kFrames - 2);
  EXPECT_EQ(diagnosticCount(*diagnostics_, "frames skipped (bad input)"), 1);
  EXPECT_EQ(diagnosticCount(*diagnostics_, "warnings: backend"), 1);
  EXPECT_EQ(diagnosticCount(*diagnostics_, "backend fallbacks (GPU failures)"), 1);
  EXPECT_NE(diagnosticValue(*diagnostics_, "last backend failure").find(kFaultText), std::string::npos)
      << diagnosticValue(*diagnostics_, "last backend failure");
  const std::string backend = diagnosticValue(*diagnostics_, "backend");
  EXPECT_EQ(backend.rfind("cpu: ", 0), 0u) << backend;
  EXPECT_NE(backend.find("fallback"), std::string::npos) << backend;
  diagnostic_msgs::DiagnosticArrayConstPtr keep;
  const diagnostic_msgs::DiagnosticStatus* status = lastStatus(keep);
  ASSERT_NE(status, nullptr);
  EXPECT_EQ(status->level, diagnostic_msgs::DiagnosticStatus::WARN) << status->message;
  EXPECT_NE(status->message.find("CPU"), std::string::npos) << status->message;

  // Exactly one warning about it on /rosout, naming the fault and the way out.
  const std::vector<std::string> lines = watcher_->all();
  int fallback_lines = 0;
  std::string warning;
  for (const std::string& line : lines) {
    if (line.find(kFaultText) == std::string::npos) continue;
    ++fallback_lines;
    warning = line;
    EXPECT_NE(line.find("continuing on the CPU"), std::string::npos) << line;
    EXPECT_NE(line.find("skipped"), std::string::npos) << line;
  }
  EXPECT_EQ(fallback_lines, 1) << dump();
  std::printf("backend_fault: %.1f s wall; fault at frame %d; pairs solved %s; warning: %s\n",
              (ros::WallTime::now() - started).toSec(), fault_frame,
              diagnosticValue(*diagnostics_, "pairs solved").c_str(), warning.c_str());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "mc_flow_backend_fault_test");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  spinner.stop();
  return result;
}
