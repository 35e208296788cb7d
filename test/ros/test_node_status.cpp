// The nodelet's counters, throttled warnings and diagnostics without a node.
#include <gtest/gtest.h>

#include "mc_flow/ros/input_gate.h"
#include "mc_flow/ros/node_status.h"

namespace mc_flow_ros {
namespace {

ros::WallTime at(double seconds) { return ros::WallTime(seconds); }

std::string diagnostic(const diagnostic_updater::DiagnosticStatusWrapper& status, const std::string& key) {
  for (const auto& kv : status.values)
    if (kv.key == key) return kv.value;
  return "(missing)";
}

TEST(NodeStatus, AWarningIsShownOncePerPeriodAndSaysHowManyWereHeldBack) {
  NodeStatus status;
  EXPECT_EQ(status.warning("stamps", "skewed", at(100)).value_or("(held)"), "skewed");
  EXPECT_FALSE(status.warning("stamps", "skewed", at(101)));
  EXPECT_FALSE(status.warning("stamps", "skewed", at(104.9)));
  // Another key is throttled on its own.
  EXPECT_TRUE(status.warning("input_stamp:/camera/rgb", "went back", at(102)));
  EXPECT_EQ(status.warning("stamps", "skewed", at(105)).value_or("(held)"),
            "skewed (2 more like this since the last such warning)");
  // Period 0: never held back.
  EXPECT_TRUE(status.warning("backend", "GPU failed", at(105)));
  EXPECT_TRUE(status.warning("backend", "GPU failed", at(105), 0.0));

  InputGate gate({"/rgb", "/depth", "/info"});
  diagnostic_updater::DiagnosticStatusWrapper d;
  status.fill(d, gate, false, at(106), 5.0);
  EXPECT_EQ(diagnostic(d, "warnings: stamps"), "4");
  EXPECT_EQ(diagnostic(d, "warnings: input_stamp"), "1");
  EXPECT_EQ(diagnostic(d, "warnings: backend"), "2");
  EXPECT_EQ(diagnostic(d, "last problem"), "GPU failed");
}

TEST(NodeStatus, TheSummarySaysIdleSilentOnTheCpuOrRunning) {
  NodeStatus status;
  InputGate gate({"/rgb", "/depth", "/info"});
  diagnostic_updater::DiagnosticStatusWrapper idle;
  status.fill(idle, gate, false, at(10), 5.0);
  EXPECT_EQ(idle.message, "idle: no listener on any output");
  gate.subscribed(at(10));
  diagnostic_updater::DiagnosticStatusWrapper silent;
  status.fill(silent, gate, true, at(20), 5.0);
  EXPECT_EQ(silent.level, diagnostic_msgs::DiagnosticStatus::WARN);
  EXPECT_EQ(silent.message, "no synchronised input");

  gate.synchronised(at(20));
  status.backendFailed("injected fault in stage labelStep of solve 3");
  diagnostic_updater::DiagnosticStatusWrapper on_cpu;
  status.fill(on_cpu, gate, true, at(21), 5.0);
  EXPECT_EQ(on_cpu.message, "running on the CPU after a GPU failure");
  EXPECT_EQ(diagnostic(on_cpu, "backend fallbacks (GPU failures)"), "1");
  EXPECT_EQ(diagnostic(on_cpu, "frames skipped (bad input)"), "1");
  EXPECT_EQ(diagnostic(on_cpu, "backend"), "cpu: fallback after a failure of the requested backend");

  mc_flow::Result result;
  result.backend = "cuda";
  result.backend_kind = mc_flow::Backend::Cuda;
  result.start = mc_flow::StartKind::Warm;
  result.timings.total = 7.5;
  status.pairSolved(result, 8.0);
  status.pairSolved(result, 10.0);
  status.frameDropped();
  diagnostic_updater::DiagnosticStatusWrapper running;
  status.fill(running, gate, true, at(22), 5.0);
  EXPECT_EQ(running.message, "running");
  EXPECT_EQ(diagnostic(running, "pairs solved"), "2");
  EXPECT_EQ(diagnostic(running, "pairs started warm"), "2");
  EXPECT_EQ(diagnostic(running, "frames dropped (arrived while solving)"), "1");
  EXPECT_EQ(std::stod(diagnostic(running, "solve time mean [ms]")), 9.0);
  EXPECT_EQ(status.framesDropped(), 1);
  EXPECT_EQ(status.pairsSolved(), 2);
}

TEST(NodeStatus, EachPipelineStepIsCountedAndWarnedInWords) {
  NodeStatus status;
  using Outcome = mc_flow::SequenceStep::Outcome;
  mc_flow::SequenceStep started;
  started.reset_key = "gap";
  started.reset_reason = "2.5 s since the previous frame (> max_pair_interval 1 s)";
  std::vector<StepWarning> w = status.recordStep(started, "12.000000000", 1.0);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].key, "reset:gap");
  EXPECT_EQ(w[0].text,
            "frame 12.000000000: 2.5 s since the previous frame (> max_pair_interval 1 s): starting a new sequence");

  mc_flow::SequenceStep repeated;
  repeated.outcome = Outcome::RepeatedStamp;
  w = status.recordStep(repeated, "12.000000000", 0.1);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].key, "stamp");

  mc_flow::SequenceStep failed;
  failed.outcome = Outcome::PairFailed;
  failed.problem = "processing_level 5 is deeper than the pyramid (3 levels at 40x30)";
  w = status.recordStep(failed, "12.100000000", 0.5);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].key, "solver");
  EXPECT_NE(w[0].text.find("pair ending at 12.100000000 skipped: processing_level 5"), std::string::npos) << w[0].text;

  mc_flow::SequenceStep gpu;
  gpu.outcome = Outcome::PairFailed;
  gpu.problem = "the cuda backend failed: an illegal memory access";
  gpu.backend_fallback = "an illegal memory access";
  w = status.recordStep(gpu, "12.200000000", 3.0);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].key, "backend");
  EXPECT_EQ(w[0].period, 0.0) << "a move to the CPU is never held back";
  EXPECT_NE(w[0].text.find("; continuing on the CPU"), std::string::npos);

  mc_flow::Result result;
  result.backend = "cpu";
  mc_flow::SequenceStep solved;
  solved.outcome = Outcome::Solved;
  solved.result = &result;
  EXPECT_TRUE(status.recordStep(solved, "12.300000000", 20.0).empty());

  InputGate gate({"/rgb", "/depth", "/info"});
  diagnostic_updater::DiagnosticStatusWrapper d;
  status.fill(d, gate, false, at(1), 5.0);
  EXPECT_EQ(diagnostic(d, "sequence resets"), "1");
  EXPECT_EQ(diagnostic(d, "frames skipped (bad input)"), "3");  // the repeat, the refused pair, the GPU's pair
  EXPECT_EQ(diagnostic(d, "backend fallbacks (GPU failures)"), "1");
  EXPECT_EQ(diagnostic(d, "pairs solved"), "1");
}

}  // namespace
}  // namespace mc_flow_ros
