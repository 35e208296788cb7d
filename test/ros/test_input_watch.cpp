// The nodelet's words when no synchronised frame arrives: never arrived, stopped, not synchronised.
#include <gtest/gtest.h>

#include "mc_flow/ros/input_watch.h"

using mc_flow_ros::describeInputSilence;
using mc_flow_ros::InputSilence;
using mc_flow_ros::InputSnapshot;

namespace {

constexpr double kWarnAfter = 5.0;

/// Three topics that each received `n` messages, the last `age` s ago, stamped `stamp`.
InputSnapshot snapshot(long n, double age, double stamp, double silent) {
  InputSnapshot s;
  const char* labels[3] = {"rgb", "depth", "camera_info"};
  const char* topics[3] = {"/camera/rgb/image_rect_color", "/camera/depth_registered/image_rect",
                           "/camera/rgb/camera_info"};
  for (int i = 0; i < 3; ++i) {
    s.topics[i].label = labels[i];
    s.topics[i].topic = topics[i];
    s.topics[i].received = n;
    s.topics[i].seconds_since_last = age;
    s.topics[i].has_stamp = n > 0;
    s.topics[i].stamp = n > 0 ? stamp : 0;
  }
  s.seconds_without_sync = silent;
  return s;
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

}  // namespace

TEST(InputWatch, SilentWhileFramesSynchronise) {
  EXPECT_FALSE(describeInputSilence(snapshot(20, 0.5, 100.0, 4.9), kWarnAfter));
  EXPECT_FALSE(describeInputSilence(snapshot(0, 4.0, 0.0, 4.0), kWarnAfter));
}

TEST(InputWatch, InputThatNeverArrivedNamesTheTopicsAndCounts) {
  InputSnapshot s = snapshot(12, 0.2, 100.0, 16.0);
  s.topics[2].received = 0;
  s.topics[2].has_stamp = false;
  s.topics[2].seconds_since_last = 16.0;
  const auto w = describeInputSilence(s, kWarnAfter);
  ASSERT_TRUE(w);
  EXPECT_EQ(w->problem, InputSilence::NeverArrived);
  EXPECT_FALSE(w->restart_synchroniser);
  EXPECT_TRUE(contains(w->text, "no synchronised input for 16 s")) << w->text;
  EXPECT_TRUE(contains(w->text, "/camera/rgb/image_rect_color (12 received)")) << w->text;
  EXPECT_TRUE(contains(w->text, "/camera/rgb/camera_info (0 received)")) << w->text;
  EXPECT_TRUE(contains(w->text, "nothing at all on /camera/rgb/camera_info")) << w->text;
  EXPECT_TRUE(contains(w->text, "missing camera_info")) << w->text;

  // Nothing on depth: camera_info is not blamed.
  InputSnapshot d = snapshot(3, 0.2, 100.0, 9.0);
  d.topics[1].received = 0;
  const auto wd = describeInputSilence(d, kWarnAfter);
  ASSERT_TRUE(wd);
  EXPECT_EQ(wd->problem, InputSilence::NeverArrived);
  EXPECT_TRUE(contains(wd->text, "nothing at all on /camera/depth_registered/image_rect")) << wd->text;
  EXPECT_FALSE(contains(wd->text, "missing camera_info")) << wd->text;
}

TEST(InputWatch, InputThatStoppedSaysSoWithCountsAndLastStamp) {
  // The end of a bag: 20 frames each, the last 16 s ago, stamped 1311868164.5.
  const auto w = describeInputSilence(snapshot(20, 16.2, 1311868164.5, 17.0), kWarnAfter);
  ASSERT_TRUE(w);
  EXPECT_EQ(w->problem, InputSilence::Stopped);
  EXPECT_FALSE(w->restart_synchroniser);
  EXPECT_TRUE(contains(w->text,
                       "no input for 16 s; 20/20/20 rgb/depth/camera_info messages received, last at t = "
                       "1311868164.500000"))
      << w->text;
  EXPECT_TRUE(contains(w->text, "input stopped")) << w->text;
  EXPECT_FALSE(contains(w->text, "camera_info is the most common cause")) << w->text;
}

TEST(InputWatch, OneInputThatStoppedIsNamed) {
  InputSnapshot s = snapshot(30, 0.3, 200.0, 12.0);
  s.topics[1].received = 18;
  s.topics[1].seconds_since_last = 11.0;
  s.topics[1].stamp = 190.25;
  const auto w = describeInputSilence(s, kWarnAfter);
  ASSERT_TRUE(w);
  EXPECT_EQ(w->problem, InputSilence::Stopped);
  EXPECT_TRUE(contains(w->text,
                       "no input on /camera/depth_registered/image_rect for 11 s while "
                       "/camera/rgb/image_rect_color and /camera/rgb/camera_info still arrive"))
      << w->text;
  EXPECT_TRUE(contains(w->text, "30/18/30")) << w->text;
  EXPECT_TRUE(contains(w->text, "depth t = 190.250000")) << w->text;
}

TEST(InputWatch, InputThatDoesNotSynchroniseSaysHowFarApartTheStampsAre) {
  InputSnapshot s = snapshot(40, 0.1, 1000.0, 8.0);
  s.topics[1].stamp = 999.75;  // depth 0.25 s behind
  s.topics[2].stamp = 1000.0;
  s.approximate_sync = true;
  s.approximate_sync_max_interval = 0.1;
  const auto w = describeInputSilence(s, kWarnAfter);
  ASSERT_TRUE(w);
  EXPECT_EQ(w->problem, InputSilence::NotSynchronised);
  EXPECT_TRUE(w->restart_synchroniser);
  EXPECT_TRUE(contains(w->text, "none were synchronised for 8 s")) << w->text;
  EXPECT_TRUE(contains(w->text, "rgb - depth +0.250 s, rgb - camera_info +0.000 s")) << w->text;
  EXPECT_TRUE(contains(w->text, "more than approximate_sync_max_interval 0.100000 s")) << w->text;

  s.approximate_sync = false;
  const auto exact = describeInputSilence(s, kWarnAfter);
  ASSERT_TRUE(exact);
  EXPECT_TRUE(contains(exact->text, "exact synchronisation needs equal stamps")) << exact->text;
}
