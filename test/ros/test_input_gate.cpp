// The inputs' gate without a node: what reaches the synchroniser, what is counted, when it restarts, what the watch
// says when synchronised frames stop.
#include <gtest/gtest.h>

#include "mc_flow/ros/input_gate.h"

namespace mc_flow_ros {
namespace {

std_msgs::Header header(double stamp, std::uint32_t seq) {
  std_msgs::Header h;
  h.stamp = ros::Time(stamp);
  h.seq = seq;
  h.frame_id = "camera_rgb_optical_frame";
  return h;
}

ros::WallTime at(double seconds) { return ros::WallTime(seconds); }

std::string diagnostic(const diagnostic_updater::DiagnosticStatusWrapper& status, const std::string& key) {
  for (const auto& kv : status.values)
    if (kv.key == key) return kv.value;
  return "(missing)";
}

/// The gate's diagnostic `key` at `now`.
std::string diagnostic(const InputGate& g, double now, const std::string& key) {
  diagnostic_updater::DiagnosticStatusWrapper status;
  g.addTo(status, at(now));
  return diagnostic(status, key);
}

const char* const kHeldBack = "held back (repeated or backward stamps) rgb / depth / camera_info";

InputGate gate() { return InputGate({"/camera/rgb", "/camera/depth", "/camera/info"}); }

TEST(InputGate, IncreasingStampsPassAndRepeatsAreHeldBackByName) {
  InputGate g = gate();
  EXPECT_TRUE(g.admit(InputGate::kRgb, header(10.0, 1), at(100)).pass);
  const InputGate::Admission second = g.admit(InputGate::kRgb, header(10.1, 2), at(100.1));
  EXPECT_TRUE(second.pass);
  EXPECT_TRUE(second.warning.empty());
  const InputGate::Admission repeat = g.admit(InputGate::kRgb, header(10.1, 3), at(100.2));
  EXPECT_FALSE(repeat.pass);
  EXPECT_FALSE(repeat.restart_synchroniser);
  EXPECT_NE(repeat.warning.find("/camera/rgb: stamp 10.100000000 repeats"), std::string::npos) << repeat.warning;
  EXPECT_NE(repeat.warning.find("(1 on this topic so far)"), std::string::npos) << repeat.warning;
  EXPECT_EQ(repeat.warning_key, "input_stamp:/camera/rgb");
  // Other topics keep their own order.
  EXPECT_TRUE(g.admit(InputGate::kDepth, header(10.1, 1), at(100.2)).pass);
}

TEST(InputGate, AJumpBackRestartsTheStreamAtMostEveryFiveSeconds) {
  InputGate g = gate();
  for (int topic = 0; topic < 3; ++topic) ASSERT_TRUE(g.admit(topic, header(50.0, 1), at(0)).pass);
  const InputGate::Admission back = g.admit(InputGate::kRgb, header(1.0, 2), at(1));
  EXPECT_TRUE(back.pass);
  EXPECT_TRUE(back.restart_synchroniser);
  EXPECT_NE(back.warning.find("went back from 50.000000000: restarting the synchroniser"), std::string::npos)
      << back.warning;
  // After the restart every topic starts afresh: depth at 1.0 passes although it was at 50 before.
  EXPECT_TRUE(g.admit(InputGate::kDepth, header(1.0, 2), at(1)).pass);
  // A second jump back within 5 s is held back instead of restarting again.
  const InputGate::Admission storm = g.admit(InputGate::kRgb, header(0.5, 3), at(3));
  EXPECT_FALSE(storm.pass);
  EXPECT_FALSE(storm.restart_synchroniser);
  // 5 s after the first restart a jump back restarts again.
  EXPECT_TRUE(g.admit(InputGate::kRgb, header(0.2, 4), at(6.5)).restart_synchroniser);
  EXPECT_EQ(diagnostic(g, 7, "synchroniser restarts"), "2");
  EXPECT_EQ(diagnostic(g, 7, kHeldBack), "1 / 0 / 0");
}

// Each topic has its own connection: after a jump back on depth, the colour message sent just before it can still
// arrive. It must not become the colour topic's start, or the new stream's colour frames (lower stamps) would be held
// back until the next restart is allowed.
TEST(InputGate, AMessageSentBeforeARestartThatArrivesAfterItIsHeldBack) {
  InputGate g = gate();
  for (int topic = 0; topic < 3; ++topic) ASSERT_TRUE(g.admit(topic, header(1.0, 1), at(0)).pass);
  ASSERT_TRUE(g.admit(InputGate::kDepth, header(0.5, 2), at(1)).restart_synchroniser);
  // The old stream's repeated colour frame, then a later one of it (a bag loop's last frames).
  const InputGate::Admission repeat = g.admit(InputGate::kRgb, header(1.0, 2), at(1.01));
  EXPECT_FALSE(repeat.pass);
  EXPECT_FALSE(repeat.restart_synchroniser);
  EXPECT_NE(repeat.warning.find("/camera/rgb: stamp 1.000000000 was sent before the stream restarted (this topic had "
                                "reached 1.000000000): message held back"),
            std::string::npos)
      << repeat.warning;
  EXPECT_FALSE(g.admit(InputGate::kRgb, header(1.1, 3), at(1.02)).pass);
  // The new stream on every topic passes, and goes on.
  EXPECT_TRUE(g.admit(InputGate::kRgb, header(0.5, 4), at(1.03)).pass);
  EXPECT_TRUE(g.admit(InputGate::kCameraInfo, header(0.5, 2), at(1.03)).pass);
  for (int topic = 0; topic < 3; ++topic) EXPECT_TRUE(g.admit(topic, header(0.6, 5), at(1.1)).pass) << topic;
  EXPECT_EQ(diagnostic(g, 2, "synchroniser restarts"), "1");
  EXPECT_EQ(diagnostic(g, 2, kHeldBack), "2 / 0 / 0");
}

// A jump back smaller than the lag between two topics: the other topic's new stream may start beyond where it had
// got to. Held back as a straggler only for a moment, it then passes.
TEST(InputGate, AfterARestartAStreamBeyondItsOldStampPassesAfterAMoment) {
  InputGate g = gate();
  ASSERT_TRUE(g.admit(InputGate::kRgb, header(0.98, 1), at(0)).pass);
  ASSERT_TRUE(g.admit(InputGate::kDepth, header(1.0, 1), at(0)).pass);
  ASSERT_TRUE(g.admit(InputGate::kDepth, header(0.99, 2), at(1)).restart_synchroniser);
  EXPECT_FALSE(g.admit(InputGate::kRgb, header(1.01, 2), at(1.5)).pass);
  EXPECT_TRUE(g.admit(InputGate::kRgb, header(1.04, 3), at(1.0 + InputGate::kStragglerSeconds)).pass);
  EXPECT_TRUE(g.admit(InputGate::kDepth, header(1.02, 3), at(2.1)).pass);
}

TEST(InputGate, GapsInHeaderSeqCountAsLostButAPublisherRestartDoesNot) {
  InputGate g = gate();
  g.admit(InputGate::kDepth, header(1, 10), at(0));
  g.admit(InputGate::kDepth, header(2, 13), at(0));    // 11 and 12 lost
  g.admit(InputGate::kDepth, header(3, 5000), at(0));  // another publisher: not a loss
  g.admit(InputGate::kDepth, header(4, 5001), at(0));
  diagnostic_updater::DiagnosticStatusWrapper status;
  g.addTo(status, at(1));
  EXPECT_EQ(diagnostic(status, "lost before the callbacks rgb / depth / camera_info (header.seq gaps)"), "0 / 2 / 0");
  EXPECT_EQ(diagnostic(status, "received rgb / depth / camera_info"), "0 / 4 / 0");
}

TEST(InputGate, TheWatchNamesAMissingCameraInfoAndStaysQuietWhileFramesSynchronise) {
  InputGate g = gate();
  g.subscribed(at(0));
  for (int i = 0; i < 10; ++i) {
    g.admit(InputGate::kRgb, header(i, i + 1), at(i * 0.1));
    g.admit(InputGate::kDepth, header(i, i + 1), at(i * 0.1));
  }
  EXPECT_FALSE(g.watch(at(3), true, 0, 5.0).warning) << "not silent for 5 s yet";
  const InputGate::Watch watch = g.watch(at(6), true, 0, 5.0);
  ASSERT_TRUE(watch.warning);
  EXPECT_EQ(watch.warning->problem, InputSilence::NeverArrived);
  EXPECT_NE(watch.warning->text.find("/camera/info (0 received)"), std::string::npos) << watch.warning->text;
  EXPECT_FALSE(watch.restart_synchroniser);
  EXPECT_TRUE(g.silent(at(6), 5.0));
  g.synchronised(at(6.5));
  EXPECT_FALSE(g.silent(at(7), 5.0));
  EXPECT_FALSE(g.watch(at(7), true, 0, 5.0).warning);
  EXPECT_EQ(g.framesSynchronised(), 1);
}

TEST(InputGate, ASynchroniserThatSeesEveryTopicButNeverFiresIsRestartedOncePerNewMessage) {
  InputGate g = gate();
  g.subscribed(at(0));
  // Every topic arrives, but the stamps never match: nothing synchronises.
  for (int i = 0; i <= 5; ++i) {
    for (int topic = 0; topic < 3; ++topic) g.admit(topic, header(i + topic * 0.3, i + 1), at(i));
    EXPECT_FALSE(g.watch(at(i), true, 0, 5.0).warning) << "second " << i;
  }
  const InputGate::Watch first = g.watch(at(6), true, 0, 5.0);
  ASSERT_TRUE(first.warning);
  EXPECT_EQ(first.warning->problem, InputSilence::NotSynchronised);
  EXPECT_TRUE(first.restart_synchroniser);
  // Nothing new since that restart: no second restart and no warning.
  const InputGate::Watch second = g.watch(at(7), true, 0, 5.0);
  EXPECT_FALSE(second.restart_synchroniser);
  EXPECT_FALSE(second.warning);
  for (int topic = 0; topic < 3; ++topic) g.admit(topic, header(20 + topic * 0.3, 20), at(7.5));
  EXPECT_TRUE(g.watch(at(8), true, 0, 5.0).restart_synchroniser);
  diagnostic_updater::DiagnosticStatusWrapper status;
  g.addTo(status, at(8));
  EXPECT_EQ(diagnostic(status, "synchroniser restarts"), "2");
}

TEST(InputGate, TheRateCountsTheLastTenSecondsOfSynchronisedFrames) {
  InputGate g = gate();
  for (int i = 0; i <= 40; ++i) g.synchronised(at(i * 0.5));  // 2 Hz for 20 s
  diagnostic_updater::DiagnosticStatusWrapper status;
  g.addTo(status, at(20));
  EXPECT_NEAR(std::stod(diagnostic(status, "input rate [Hz]")), 2.0, 1e-9);
  EXPECT_EQ(diagnostic(status, "frames synchronised"), "41");
}

TEST(InputGate, RgbAndDepthStampsFurtherApartThanAllowedAreNamed) {
  EXPECT_FALSE(stampDifferenceWarning(ros::Time(3000.6), ros::Time(3000.62), 0.03));
  EXPECT_FALSE(stampDifferenceWarning(ros::Time(3000.6), ros::Time(3000.6), 0.0));
  EXPECT_EQ(stampDifferenceWarning(ros::Time(3000.6), ros::Time(3000.65), 0.03).value_or("(none)"),
            "RGB stamp 3000.600000000 and depth stamp 3000.650000000 differ by 0.050000 s (> max_stamp_difference "
            "0.030000 s): motion between them biases the result; check the camera's sync settings");
  // Depth first: the same difference.
  EXPECT_NE(stampDifferenceWarning(ros::Time(10.0), ros::Time(9.9), 0.03).value_or("").find("differ by 0.100000 s"),
            std::string::npos);
}

}  // namespace
}  // namespace mc_flow_ros
