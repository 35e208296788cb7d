// Stream mode at the node level (docs/STREAMS.md), with the nodelet's defaults (warm_start on): the first pair of
// a sequence starts cold and every later one warm, which ~segments says (SegmentArray.start) and /diagnostics
// count; the background keeps its id from pair to pair; stamps going back (a bag loop) reset the sequence with a
// warning, and the pair after the reset starts cold, with ids above every earlier one, the one after it warm
// again. Frames go in lockstep (each after the previous pair's output), so none is dropped and every pair is the
// one the test means.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include <diagnostic_msgs/DiagnosticArray.h>

#include "mc_flow/SegmentArray.h"
#include "rostest_common.h"

using mcflow_test::Collector;
using mcflow_test::diagnosticCount;
using mcflow_test::diagnosticValue;
using mcflow_test::largestId;
using mcflow_test::RosoutWatcher;
using mcflow_test::solvePair;
using mcflow_test::startSequence;
using mcflow_test::SyntheticCamera;
using mcflow_test::waitFor;

namespace {

constexpr int kWidth = 160, kHeight = 120;  // processed as they are (automatic downsampling: factor 1)
constexpr int kFrames = 5;                  // pairs 1..4 before the reset
const ros::Time kStart(7000.0);
const ros::Duration kInterval(0.1);

}  // namespace

class Stream : public ::testing::Test {
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

  mc_flow::SegmentArray::ConstPtr solve(int t, const ros::Time& stamp) {
    return solvePair(*camera_, *segments_, t, stamp);
  }
  void start(int t, const ros::Time& stamp) { startSequence(*camera_, t, stamp); }

  ros::NodeHandle nh_;
  std::unique_ptr<SyntheticCamera> camera_;
  std::unique_ptr<RosoutWatcher> watcher_;
  std::unique_ptr<Collector<mc_flow::SegmentArray>> segments_;
  std::unique_ptr<Collector<diagnostic_msgs::DiagnosticArray>> diagnostics_;
};

TEST_F(Stream, PairsAfterTheFirstStartWarmIdsPersistAndAResetStartsCold) {
  // ---- One sequence: pair 1 cold (nothing to carry), pairs 2..4 warm from the previous pair.
  start(0, kStart);
  std::vector<mc_flow::SegmentArray::ConstPtr> pairs;
  for (int t = 1; t < kFrames; ++t) {
    pairs.push_back(solve(t, kStart + kInterval * t));
    ASSERT_TRUE(pairs.back()) << "no ~segments for pair " << t << watcher_->dump();
  }
  EXPECT_EQ(pairs[0]->start, "cold");
  for (std::size_t k = 1; k < pairs.size(); ++k) {
    EXPECT_EQ(pairs[k]->start, "warm") << "pair " << k + 1 << ": " << pairs[k]->start_note;
    // A warm pair has no note, unless the energy check ran a cold solve that did no better and kept the warm one.
    EXPECT_TRUE(pairs[k]->start_note.empty() ||
                pairs[k]->start_note.find("the warm result is kept") != std::string::npos)
        << "pair " << k + 1 << ": " << pairs[k]->start_note;
  }
  // Ids persist: the background has one id throughout, and most ids of a pair are there in the next.
  const std::uint32_t background = largestId(*pairs[0]);
  EXPECT_GT(background, 0u);
  for (std::size_t k = 1; k < pairs.size(); ++k) {
    EXPECT_EQ(largestId(*pairs[k]), background) << "pair " << k + 1;
    std::set<std::uint32_t> before, kept;
    for (const auto& s : pairs[k - 1]->segments) before.insert(s.id);
    for (const auto& s : pairs[k]->segments)
      if (before.count(s.id)) kept.insert(s.id);
    EXPECT_GE(2 * kept.size(), before.size())
        << "pair " << k + 1 << " kept " << kept.size() << " of " << before.size() << " ids";
  }

  // ---- The stamps go back 5 s (a bag looping): a warned reset; the next pair cold, the one after warm.
  const ros::Time loop = kStart + kInterval * (kFrames - 1) - ros::Duration(5.0);
  start(0, loop);
  EXPECT_TRUE(waitFor([&] { return watcher_->seen("(stream reset or bag loop): starting a new sequence"); }, 10.0))
      << watcher_->dump();
  EXPECT_TRUE(watcher_->seen("the stamp went back by ")) << watcher_->dump();
  const auto after_reset = solve(1, loop + kInterval);
  ASSERT_TRUE(after_reset) << "no pair solved after the reset" << watcher_->dump();
  EXPECT_EQ(after_reset->start, "cold") << "the reset left a prior: " << after_reset->start_note;
  // A new sequence takes no earlier id (its TF frames would be those of unrelated segments).
  std::uint32_t highest_before = 0;
  for (const auto& pair : pairs)
    for (const auto& s : pair->segments) highest_before = std::max(highest_before, s.id);
  for (const auto& s : after_reset->segments)
    EXPECT_GT(s.id, highest_before) << "id " << s.id << " after the reset was handed out before it";
  const auto next = solve(2, loop + kInterval * 2);
  ASSERT_TRUE(next) << "no second pair after the reset" << watcher_->dump();
  EXPECT_EQ(next->start, "warm") << next->start_note;

  // ---- /diagnostics count the same: 3 + 1 warm starts, no fallback, one reset.
  EXPECT_TRUE(waitFor([&] { return diagnosticCount(*diagnostics_, "pairs solved") >= kFrames + 1; }, 10.0));
  EXPECT_EQ(diagnosticCount(*diagnostics_, "pairs started warm"), kFrames - 1);
  EXPECT_EQ(diagnosticCount(*diagnostics_, "pairs started cold after a refused warm start"), 0);
  EXPECT_EQ(diagnosticCount(*diagnostics_, "sequence resets"), 1);
  EXPECT_EQ(diagnosticValue(*diagnostics_, "last start"), "warm");
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "rostest_stream");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
