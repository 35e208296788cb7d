// The static world's prior from TF at the node level (docs/ALGORITHM.md, "Static world and odometry"): the nodelet runs
// with prior_frame "wheel_odom" (prior_frame.test), and the test broadcasts the TF wheel_odom -> camera optical frame
// at each frame's stamp, as another odometry would. The synthetic camera stands still, so the transform is the
// identity at every stamp and agrees with the images. What a user sees:
// - with the transform, every pair's world is chosen by the prior (SegmentArray.world_chosen_by "prior"), the world is
//   the background and the parts that move are flagged, and no prior warning is logged;
// - without it (a new sequence whose stamps have no transform), every pair is still solved, its world chosen otherwise,
//   and the missing transform is warned about on /rosout, throttled (/diagnostics count every miss); once the
//   transform is back, the first pair whose two frames both have a pose is chosen by the prior again;
// - a nodelet loaded with prior_frame equal to the odom_frame it broadcasts warns at start-up.
// Frames go in lockstep (each after the previous pair's output), and the transforms of a stretch are broadcast before
// its first image, so each lookup finds its stamp whatever the machine's speed.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <nodelet/NodeletLoad.h>
#include <nodelet/NodeletUnload.h>
#include <ros/master.h>
#include <tf2_msgs/TFMessage.h>

#include "mc_flow/SegmentArray.h"
#include "rostest_common.h"

using mcflow_test::Collector;
using mcflow_test::diagnosticCount;
using mcflow_test::largestId;
using mcflow_test::RosoutWatcher;
using mcflow_test::solvePair;
using mcflow_test::startSequence;
using mcflow_test::SyntheticCamera;
using mcflow_test::waitFor;

namespace {

constexpr int kWidth = 160, kHeight = 120;  // processed as they are (automatic downsampling: factor 1)
constexpr const char* kPriorFrame = "wheel_odom";
constexpr const char* kMissingPrior = "no static-world prior for frame";
constexpr double kWarningPeriod = 5.0;  // s, the nodelet's throttle of a repeated warning
const ros::Duration kInterval(0.1);

/// The publishers of `topic` the master knows (node names).
std::set<std::string> publishersOf(const std::string& topic) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  std::set<std::string> nodes;
  if (!ros::master::execute("getSystemState", args, result, payload, true)) return nodes;
  XmlRpc::XmlRpcValue& publishers = payload[0];
  for (int i = 0; i < publishers.size(); ++i) {
    if (std::string(publishers[i][0]) != topic) continue;
    for (int k = 0; k < publishers[i][1].size(); ++k) nodes.insert(std::string(publishers[i][1][k]));
  }
  return nodes;
}

}  // namespace

class PriorFrame : public ::testing::Test {
 protected:
  void SetUp() override {
    camera_ = std::make_unique<SyntheticCamera>(nh_, kWidth, kHeight);
    watcher_ = std::make_unique<RosoutWatcher>(nh_);
    segments_ = std::make_unique<Collector<mc_flow::SegmentArray>>(nh_, "/mc_flow/segments");
    diagnostics_ = std::make_unique<Collector<diagnostic_msgs::DiagnosticArray>>(nh_, "/diagnostics");
    // What tf2_ros::TransformBroadcaster does, through a handle whose subscribers can be counted: the nodelet's
    // listener must be connected before a transform is sent.
    tf_ = nh_.advertise<tf2_msgs::TFMessage>("/tf", 100);
    ASSERT_TRUE(waitFor([this] { return camera_->inputSubscribers() >= 3; }, 60.0)) << "the nodelet never subscribed";
    ASSERT_TRUE(waitFor([this] { return tf_.getNumSubscribers() >= 1; }, 60.0))
        << "no TF listener (is prior_frame set in prior_frame.test?)";
    ASSERT_TRUE(waitFor([this] { return diagnosticCount(*diagnostics_, "pairs solved") >= 0; }, 30.0))
        << "no diagnostics";
    ASSERT_TRUE(waitFor([this] { return rosoutConnected(); }, 30.0)) << "/rosout not connected to every publisher";
  }

  /// The watcher hears every node that logs (a warning logged before is lost).
  bool rosoutConnected() const {
    const std::set<std::string> publishers = publishersOf("/rosout");
    return publishers.count("/manager") && watcher_->publishers() >= int(publishers.size());
  }

  /// Broadcasts wheel_odom -> camera at each stamp: the identity, as the synthetic camera stands still.
  void broadcastStandingCamera(const std::vector<ros::Time>& stamps) {
    tf2_msgs::TFMessage msg;
    for (const ros::Time& stamp : stamps) {
      geometry_msgs::TransformStamped t;
      t.header.stamp = stamp;
      t.header.frame_id = kPriorFrame;
      t.child_frame_id = SyntheticCamera::frameId();
      t.transform.rotation.w = 1.0;
      msg.transforms.push_back(t);
    }
    tf_.publish(msg);
    // The transforms go ahead of the images on another connection; the nodelet waits 20 ms for one.
    ros::WallDuration(1.0).sleep();
  }

  mc_flow::SegmentArray::ConstPtr solve(int t, const ros::Time& stamp) {
    return solvePair(*camera_, *segments_, t, stamp);
  }
  void start(int t, const ros::Time& stamp) { startSequence(*camera_, t, stamp); }

  /// The world is the background (the largest segment), and what moves is not the world.
  static void expectTheBackgroundIsTheWorld(const mc_flow::SegmentArray& pair, const std::string& which) {
    int world = 0, moving = 0;
    for (const auto& s : pair.segments) {
      world += s.world ? 1 : 0;
      moving += s.moving ? 1 : 0;
      EXPECT_FALSE(s.world && s.moving) << which << ", segment " << s.id;
      if (s.id == largestId(pair)) EXPECT_TRUE(s.world) << which << ": the background is not the world";
    }
    EXPECT_GE(world, 1) << which;
    EXPECT_GE(moving, 1) << which << ": the synthetic parts move";
  }

  ros::NodeHandle nh_;
  ros::Publisher tf_;
  std::unique_ptr<SyntheticCamera> camera_;
  std::unique_ptr<RosoutWatcher> watcher_;
  std::unique_ptr<Collector<mc_flow::SegmentArray>> segments_;
  std::unique_ptr<Collector<diagnostic_msgs::DiagnosticArray>> diagnostics_;
};

TEST_F(PriorFrame, WithTheTransformTheWorldIsChosenByThePrior) {
  const ros::Time t0(2000.0);
  constexpr int kFrames = 4;
  std::vector<ros::Time> stamps;
  for (int t = 0; t < kFrames; ++t) stamps.push_back(t0 + kInterval * t);
  broadcastStandingCamera(stamps);
  start(0, stamps[0]);
  for (int t = 1; t < kFrames; ++t) {
    const auto pair = solve(t, stamps[std::size_t(t)]);
    const std::string which = "pair " + std::to_string(t);
    ASSERT_TRUE(pair) << "no ~segments for " << which << watcher_->dump();
    EXPECT_EQ(pair->world_chosen_by, "prior") << which << watcher_->dump();
    expectTheBackgroundIsTheWorld(*pair, which);
  }
  EXPECT_EQ(watcher_->count(kMissingPrior), 0) << watcher_->dump();
}

TEST_F(PriorFrame, WithoutTheTransformItWarnsFallsBackAndTakesThePriorAgainOnceItIsBack) {
  // A new sequence (1000 s after any transform sent): no lookup finds one.
  const ros::Time t0(3000.0);
  constexpr int kMissing = 4, kFrames = 7;  // frames 0..3 have no transform, 4..6 have one
  std::vector<ros::Time> stamps;
  for (int t = 0; t < kFrames; ++t) stamps.push_back(t0 + kInterval * t);
  const long misses_before = std::max(0L, diagnosticCount(*diagnostics_, "warnings: prior"));
  const ros::WallTime begin = ros::WallTime::now();
  start(0, stamps[0]);
  for (int t = 1; t < kMissing; ++t) {
    const auto pair = solve(t, stamps[std::size_t(t)]);
    const std::string which = "pair " + std::to_string(t) + " without a transform";
    ASSERT_TRUE(pair) << "no ~segments for " << which << ": the nodelet must go on" << watcher_->dump();
    // Chosen otherwise: the widest segment (or the one behind it), then the previous pair's world.
    const std::set<std::string> fallbacks = {"widest", "previous", "outgrown", "behind"};
    EXPECT_TRUE(fallbacks.count(pair->world_chosen_by)) << which << ": '" << pair->world_chosen_by << "'";
    expectTheBackgroundIsTheWorld(*pair, which);
  }
  // Every miss is counted; the warning names the frames and is shown at most once per period.
  EXPECT_TRUE(
      waitFor([&] { return diagnosticCount(*diagnostics_, "warnings: prior") >= misses_before + kMissing; }, 30.0))
      << "/diagnostics count " << diagnosticCount(*diagnostics_, "warnings: prior") << " missed transforms";
  EXPECT_TRUE(waitFor([&] { return watcher_->seen(kMissingPrior); }, 10.0)) << watcher_->dump();
  EXPECT_TRUE(
      watcher_->seen("no transform from prior_frame 'wheel_odom' to '" + std::string(SyntheticCamera::frameId()) + "'"))
      << watcher_->dump();
  const double elapsed = (ros::WallTime::now() - begin).toSec();
  EXPECT_LE(watcher_->count(kMissingPrior), 1 + int(elapsed / kWarningPeriod)) << watcher_->dump();

  // The transform is back from frame 4: pair 3 -> 4 has one pose only (no prior), pairs 4 -> 5 and 5 -> 6 have both.
  broadcastStandingCamera({stamps.begin() + kMissing, stamps.end()});
  const auto half = solve(kMissing, stamps[kMissing]);
  ASSERT_TRUE(half) << "no ~segments for pair " << kMissing << watcher_->dump();
  EXPECT_NE(half->world_chosen_by, "prior") << "a prior from one pose";
  for (int t = kMissing + 1; t < kFrames; ++t) {
    const auto pair = solve(t, stamps[std::size_t(t)]);
    const std::string which = "pair " + std::to_string(t) + " with the transform back";
    ASSERT_TRUE(pair) << "no ~segments for " << which << watcher_->dump();
    EXPECT_EQ(pair->world_chosen_by, "prior") << which << watcher_->dump();
    expectTheBackgroundIsTheWorld(*pair, which);
  }
}

TEST_F(PriorFrame, APriorFrameThatIsItsOwnOdomFrameIsWarnedAbout) {
  // A second nodelet in the same manager, loaded now that /rosout is heard; no remapping: its inputs are silent
  // topics, so it solves nothing and broadcasts no transform.
  const std::string name = "/mc_flow_own_prior";
  ros::param::set(name + "/prior_frame", "odom");  // the default odom_frame
  ros::param::set(name + "/publish_odom_tf", true);
  ASSERT_TRUE(ros::service::waitForService("/manager/load_nodelet", ros::Duration(30.0)));
  nodelet::NodeletLoad load;
  load.request.name = name;
  load.request.type = "mc_flow/MCFlowNodelet";
  ASSERT_TRUE(ros::service::call("/manager/load_nodelet", load));
  EXPECT_TRUE(load.response.success);
  EXPECT_TRUE(
      waitFor([&] { return watcher_->seen("prior_frame 'odom' is the odom_frame this node broadcasts"); }, 30.0))
      << watcher_->dump();
  nodelet::NodeletUnload unload;
  unload.request.name = name;
  EXPECT_TRUE(ros::service::call("/manager/unload_nodelet", unload));
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "rostest_prior_frame");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
