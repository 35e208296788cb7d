// Bad input: unsupported encodings, size/aspect mismatch, all-invalid depth, zero intrinsics, repeated and
// out-of-order stamps, a stream reset, RGB/depth stamp skew, silent camera_info. The node must warn (naming
// the value), skip the frame and keep solving afterwards.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>

#include <diagnostic_msgs/DiagnosticArray.h>

#include "mc_flow/SegmentArray.h"
#include "rostest_common.h"

using mcflow_test::Collector;
using mcflow_test::diagnosticValue;
using mcflow_test::RosoutWatcher;
using mcflow_test::SyntheticCamera;
using mcflow_test::waitFor;

namespace {

const ros::Time kStart(3000.0);

std::string dumpWarnings(const RosoutWatcher& watcher) {
  std::string all;
  for (const auto& m : watcher.all()) all += "\n  " + m;
  return all;
}

/// The three numbers of a diagnostic value "a / b / c"; false when it is missing.
bool threeCounts(const std::string& value, long counts[3]) {
  return std::sscanf(value.c_str(), "%ld / %ld / %ld", &counts[0], &counts[1], &counts[2]) == 3;
}

}  // namespace

class BadInput : public ::testing::Test {
 protected:
  void SetUp() override {
    camera_ = std::make_unique<SyntheticCamera>(nh_, 320, 240);
    watcher_ = std::make_unique<RosoutWatcher>(nh_);
    segments_ = std::make_unique<Collector<mc_flow::SegmentArray>>(nh_, "/mc_flow/segments");
    diagnostics_ = std::make_unique<Collector<diagnostic_msgs::DiagnosticArray>>(nh_, "/diagnostics");
    ASSERT_TRUE(waitFor([this] { return camera_->inputSubscribers() >= 3; }, 60.0)) << "the nodelet never subscribed";
    ros::WallDuration(1.0).sleep();
  }

  // The next test's camera re-advertises the topics: whatever this one sent must have arrived first.
  void TearDown() override { waitUntilCounted(); }

  /// Publishes one triple (counted, see waitUntilCounted).
  void publish(const sensor_msgs::ImagePtr& rgb, const sensor_msgs::ImagePtr& depth,
               const sensor_msgs::CameraInfoPtr& info) {
    camera_->publish(rgb, depth, info);
    for (long& n : published_) ++n;
  }
  void publish(int t, const ros::Time& stamp) {
    publish(camera_->rgb(t, stamp), camera_->depth(t, stamp), camera_->info(stamp));
  }

  /// @brief Waits until the nodelet's diagnostics count every message this process published to its inputs (received,
  /// or lost before its callback). Each topic has its own connection, so one topic's message can overtake another's
  /// earlier one: a case that starts only after this cannot have its messages mixed with the previous case's.
  void waitUntilCounted() {
    long received[3] = {-1, -1, -1}, lost[3] = {0, 0, 0};
    auto counted = [&] {
      if (!threeCounts(diagnosticValue(*diagnostics_, "received rgb / depth / camera_info"), received)) return false;
      threeCounts(
          diagnosticValue(*diagnostics_, "lost before the callbacks rgb / depth / camera_info (header.seq gaps)"),
          lost);
      for (int i = 0; i < 3; ++i)
        if (received[i] + lost[i] < published_[i]) return false;
      return true;
    };
    EXPECT_TRUE(waitFor(counted, 15.0)) << "published rgb / depth / camera_info " << published_[0] << " / "
                                        << published_[1] << " / " << published_[2] << ", the nodelet received "
                                        << received[0] << " / " << received[1] << " / " << received[2] << " and lost "
                                        << lost[0] << " / " << lost[1] << " / " << lost[2];
  }

  /// Publishes one (possibly broken) triple, waits for a warning containing `expected`, then until the nodelet has
  /// counted the triple's every message.
  void expectWarning(const sensor_msgs::ImagePtr& rgb, const sensor_msgs::ImagePtr& depth,
                     const sensor_msgs::CameraInfoPtr& info, const std::string& expected) {
    publish(rgb, depth, info);
    EXPECT_TRUE(waitFor([&] { return watcher_->seen(expected); }, 15.0))
        << "no warning containing \"" << expected << "\"; warnings seen:" << dumpWarnings(*watcher_);
    waitUntilCounted();
  }

  ros::Time stamp(double seconds) const { return kStart + ros::Duration(seconds); }

  ros::NodeHandle nh_;
  std::unique_ptr<SyntheticCamera> camera_;
  std::unique_ptr<RosoutWatcher> watcher_;
  std::unique_ptr<Collector<mc_flow::SegmentArray>> segments_;
  std::unique_ptr<Collector<diagnostic_msgs::DiagnosticArray>> diagnostics_;
  /// Messages published to the nodelet's rgb, depth and camera_info inputs by every test of this process (the
  /// nodelet's counts are since its start).
  static long published_[3];
};

long BadInput::published_[3] = {0, 0, 0};

TEST_F(BadInput, EveryCaseWarnsAndTheNodeKeepsSolving) {
  // 1. camera_info missing: images alone never synchronise; the warning names the silent topic.
  {
    ros::NodeHandle nh;
    ros::Publisher rgb = nh.advertise<sensor_msgs::Image>("/camera/rgb/image_rect_color", 5);
    ros::Publisher depth = nh.advertise<sensor_msgs::Image>("/camera/depth_registered/image_rect", 5);
    ASSERT_TRUE(waitFor([&] { return rgb.getNumSubscribers() > 0 && depth.getNumSubscribers() > 0; }, 10.0));
    for (int i = 0; i < 40 && !watcher_->seen("no synchronised input"); ++i) {
      rgb.publish(camera_->rgb(0, stamp(-10 + 0.1 * i)));
      depth.publish(camera_->depth(0, stamp(-10 + 0.1 * i)));
      ++published_[0];
      ++published_[1];
      ros::WallDuration(0.1).sleep();
    }
    EXPECT_TRUE(waitFor([&] { return watcher_->seen("no synchronised input"); }, 10.0)) << dumpWarnings(*watcher_);
    EXPECT_TRUE(watcher_->seen("/camera/rgb/camera_info (0 received)")) << dumpWarnings(*watcher_);
    waitUntilCounted();
  }

  // 2. Unsupported colour encoding.
  auto rgb = camera_->rgb(0, stamp(0.0));
  rgb->encoding = "yuv422";
  expectWarning(rgb, camera_->depth(0, stamp(0.0)), camera_->info(stamp(0.0)), "unsupported colour encoding 'yuv422'");

  // 3. Unsupported depth encoding.
  auto depth = camera_->depth(0, stamp(0.1));
  depth->encoding = "8UC4";
  expectWarning(camera_->rgb(0, stamp(0.1)), depth, camera_->info(stamp(0.1)), "unsupported depth encoding '8UC4'");

  // 4. Depth of another aspect ratio than the colour image.
  depth = camera_->depth(0, stamp(0.2));
  depth->height = 180;
  depth->data.resize(std::size_t(depth->step) * depth->height);
  expectWarning(camera_->rgb(0, stamp(0.2)), depth, camera_->info(stamp(0.2)), "depth 320x180 have different aspect");

  // 5. No valid depth at all.
  depth = camera_->depth(0, stamp(0.3), "16UC1");
  std::fill(depth->data.begin(), depth->data.end(), 0);
  expectWarning(camera_->rgb(0, stamp(0.3)), depth, camera_->info(stamp(0.3)), "has no valid pixel");

  // 6. Uncalibrated camera: zero intrinsics.
  auto info = camera_->info(stamp(0.4));
  info->K.fill(0.0);
  info->P.fill(0.0);
  expectWarning(camera_->rgb(0, stamp(0.4)), camera_->depth(0, stamp(0.4)), info, "fx=0");

  // 7. A repeated stamp: the first frame is kept, its duplicate skipped.
  publish(0, stamp(1.0));
  waitUntilCounted();
  expectWarning(camera_->rgb(1, stamp(1.0)), camera_->depth(1, stamp(1.0)), camera_->info(stamp(1.0)),
                "repeats the previous");

  // 8. Stamps going back (bag loop / driver restart): a new sequence starts. Its frame reaching the solver shows that
  // every message of this case arrived (and, each topic's messages arriving in order, every one before it), without
  // waiting for the diagnostics: case 9 must follow the last synchronised frame closely (see there).
  publish(camera_->rgb(0, stamp(0.5)), camera_->depth(0, stamp(0.5)), camera_->info(stamp(0.5)));
  EXPECT_TRUE(waitFor([&] { return watcher_->seen("went back from 3001.000000000"); }, 15.0))
      << dumpWarnings(*watcher_);
  EXPECT_TRUE(waitFor([&] { return watcher_->seen("frame 3000.500000000: the stamp went back by"); }, 15.0))
      << dumpWarnings(*watcher_);

  // 9. RGB and depth 50 ms apart (max_stamp_difference 20 ms): warned, still solved as a pair. The
  // approximate synchroniser releases such a set only when a later frame shows that no better match comes, whatever
  // the order in which the two frames' messages arrive; so the later frame follows at once: a synchroniser that holds
  // messages of every topic with no frame released for no_input_warning_after (2 s) is restarted by the node's watch,
  // and the held set with it.
  const std::size_t solved_before = segments_->count();
  publish(camera_->rgb(1, stamp(0.6)), camera_->depth(1, stamp(0.65)), camera_->info(stamp(0.6)));
  publish(2, stamp(0.7));
  EXPECT_TRUE(waitFor([&] { return watcher_->seen("differ by"); }, 15.0)) << dumpWarnings(*watcher_);
  EXPECT_TRUE(watcher_->seen("RGB stamp 3000.600000000 and depth stamp 3000.650000000")) << dumpWarnings(*watcher_);
  EXPECT_TRUE(waitFor([&] { return segments_->count() > solved_before; }, 90.0)) << "no pair solved after bad input";

  // 10. A long gap starts a new sequence; the node still solves the next pair.
  // Frames keep coming (a camera does), so the node may also restart its synchroniser on the way.
  auto solvedAfterGap = [&] {
    for (const auto& m : segments_->messages()) {
      if (m->previous_stamp >= stamp(5.0)) return true;
    }
    return false;
  };
  for (int i = 0; i < 100 && !solvedAfterGap(); ++i) {
    publish(i % 4, stamp(5.0 + 0.1 * i));
    ros::WallDuration(0.3).sleep();
  }
  EXPECT_TRUE(watcher_->seen("exceeds max_pair_interval")) << dumpWarnings(*watcher_);
  ASSERT_TRUE(waitFor(solvedAfterGap, 30.0)) << "the node stopped solving (or paired across the gap)";
  // Every pair ever published chains frames less than max_pair_interval apart.
  for (const auto& m : segments_->messages()) {
    const double dt = (m->header.stamp - m->previous_stamp).toSec();
    EXPECT_GT(dt, 0.0);
    EXPECT_LE(dt, 1.0);
  }
}

// Crafted headers that made cv_bridge/OpenCV read far out of bounds (exit -11 of the manager): a 32-bit
// `height * step` equal to the data size. The manager must stay alive, name the problem, and answer the
// next valid pair.
TEST_F(BadInput, CraftedHeadersNeverKillTheManager) {
  const ros::Time base = stamp(100.0);
  publish(0, base);  // a valid frame first, so that a pair is pending
  struct Craft {
    bool colour;
    std::string encoding;
    std::uint32_t width, bytes_per_pixel;
  };
  // 4096 rows x 1048578 bytes = 2^32 + 8192 bytes, with 8192 bytes of data.
  const std::vector<Craft> crafts = {{false, "16UC1", 5461, 2},
                                     {false, "32FC1", 640, 4},
                                     {true, "rgb8", 640, 3},
                                     {true, "mono16", 640, 2},
                                     {true, "bgra8", 640, 4}};
  double t = 0.1;
  for (const Craft& c : crafts) {
    SCOPED_TRACE(c.encoding);
    auto rgb = camera_->rgb(0, base + ros::Duration(t));
    auto depth = camera_->depth(0, base + ros::Duration(t), "16UC1");
    sensor_msgs::ImagePtr& target = c.colour ? rgb : depth;
    target->encoding = c.encoding;
    target->width = c.width;
    target->height = 4096;
    target->step = 1048578;
    target->data.assign(8192, 0x11);
    // The partner keeps its aspect ratio out of the way: it is refused for the crafted image first.
    expectWarning(rgb, depth, camera_->info(base + ros::Duration(t)),
                  "4294975488 bytes, but 8192 bytes of data are present");
    t += 0.1;
  }
  // An odd step for 16UC1 is a named layout problem, not OpenCV's "Step must be a multiple of esz1".
  auto odd = camera_->depth(0, base + ros::Duration(t), "16UC1");
  odd->step += 1;
  odd->data.resize(std::size_t(odd->step) * odd->height);
  expectWarning(camera_->rgb(0, base + ros::Duration(t)), odd, camera_->info(base + ros::Duration(t)),
                "is not a multiple of the 2-byte value size");
  EXPECT_FALSE(watcher_->seen("unexpected error")) << dumpWarnings(*watcher_);

  // Still alive: the next valid frames give a pair.
  const ros::Time resume = base + ros::Duration(0.8);
  auto solvedAfter = [&] {
    for (const auto& m : segments_->messages()) {
      if (m->previous_stamp >= resume) return true;
    }
    return false;
  };
  for (int i = 0; i < 60 && !solvedAfter(); ++i) {
    publish(i % 4, resume + ros::Duration(0.1 * i));
    ros::WallDuration(0.3).sleep();
  }
  EXPECT_TRUE(waitFor(solvedAfter, 30.0)) << "no pair solved after the crafted messages";
}

// A storm of stamps going back and repeating on every topic: the synchroniser is restarted at most every
// few seconds (not per message), message_filters' "arrived out of order" warning cannot re-arm, our own
// warnings say how many they held back, and the diagnostics count each kind.
TEST_F(BadInput, StampStormIsCountedNotRepeated) {
  const ros::Time base = stamp(200.0);
  for (int i = 0; i < 40; ++i) {
    const ros::Time t = base + ros::Duration(i % 2 == 0 ? 0.05 * i : -0.05 * i);  // forward, back, forward, ...
    publish(i % 4, t);
    ros::WallDuration(0.05).sleep();
  }
  ros::WallDuration(1.0).sleep();
  int out_of_order = 0;
  for (const auto& m : watcher_->all()) out_of_order += m.find("arrived out of order") != std::string::npos ? 1 : 0;
  EXPECT_LE(out_of_order, 1) << dumpWarnings(*watcher_);
  EXPECT_TRUE(watcher_->seen("held back from the synchroniser")) << dumpWarnings(*watcher_);
  // The diagnostics count what the throttle hid.
  auto heldBackReported = [&] {
    for (const auto& array : diagnostics_->messages()) {
      for (const auto& status : array->status) {
        for (const auto& kv : status.values) {
          if (kv.key.rfind("held back (repeated or backward stamps)", 0) == 0 && kv.value != "0 / 0 / 0") return true;
        }
      }
    }
    return false;
  };
  EXPECT_TRUE(waitFor(heldBackReported, 10.0)) << "no held-back count in /diagnostics";
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "mc_flow_bad_input_test");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  spinner.stop();
  return result;
}
