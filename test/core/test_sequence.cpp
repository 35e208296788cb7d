// The ROS-free stream pipeline: preprocessing rule, pairing and resets, warm starts, tracks.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "mc_flow/core/error.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/testing/synthetic_scene.h"

namespace mc_flow {
namespace {

TEST(Downsampling, ChoosesThePowerOfTwoClosestTo320) {
  EXPECT_EQ(chooseDownsample(0, 320), 1);
  EXPECT_EQ(chooseDownsample(0, 640), 2);
  EXPECT_EQ(chooseDownsample(0, 1280), 4);
  EXPECT_EQ(chooseDownsample(0, 160), 1);
  EXPECT_EQ(chooseDownsample(4, 640), 4);
  EXPECT_THROW(chooseDownsample(3, 640), ConfigError);
  EXPECT_THROW(chooseDownsample(-1, 640), ConfigError);
}

TEST(Downsampling, UsesThePyramidRuleAcrossDepthEdges) {
  RgbdFrame f;
  f.intensity = ImageF(8, 6, 1, 0.5f);
  f.depth = ImageF(8, 6, 1, 1.0f);
  for (int y = 0; y < 6; ++y)
    for (int x = 4; x < 8; ++x) f.depth(x, y) = 3.0f;  // a depth edge between columns 3 and 4
  f.depth(0, 0) = std::numeric_limits<float>::quiet_NaN();
  const RgbdFrame half = downsampleFrame(f, 2, 0.1);
  ASSERT_EQ(half.width(), 4);
  ASSERT_EQ(half.height(), 3);
  // Not averaged across the edge (a block average would give 2 m next to it).
  EXPECT_FLOAT_EQ(half.depth(1, 1), 1.0f);
  EXPECT_FLOAT_EQ(half.depth(2, 1), 3.0f);
  EXPECT_FLOAT_EQ(half.depth(0, 0), 1.0f) << "the NaN is invalid, not averaged in";
  EXPECT_NEAR(half.intensity(1, 1), 0.5f, 1e-6);
  const RgbdFrame quarter = downsampleFrame(f, 4, 0.1);
  EXPECT_EQ(quarter.width(), 2);
  EXPECT_THROW(downsampleFrame(f, 3, 0.1), ConfigError);
}

StreamFrame syntheticFrame(int t, double stamp, int variant = 0) {
  SyntheticSceneOptions o;
  o.width = 160;
  o.height = 120;
  o.variant = variant;
  o.stream_events = true;
  StreamFrame f;
  ImageU8 colour;
  renderSyntheticFrame(o, t, f.frame, colour, f.K);
  f.stamp = stamp;
  f.source = "camera";
  f.extra = t;
  return f;
}

TEST(SequencePipeline, PairsFramesWarmStartsAndTracksSegments) {
  Config config;
  SequencePipeline pipeline(config, 0, 0.5);
  SequenceStep s0 = pipeline.push(syntheticFrame(0, 10.0));
  EXPECT_EQ(s0.outcome, SequenceStep::Outcome::Started);
  EXPECT_TRUE(s0.reset_key.empty());
  SequenceStep s1 = pipeline.push(syntheticFrame(1, 10.033));
  ASSERT_EQ(s1.outcome, SequenceStep::Outcome::Solved) << s1.problem;
  EXPECT_EQ(s1.result->start, StartKind::Cold);
  EXPECT_EQ(std::any_cast<int>(s1.first->extra), 0);
  EXPECT_EQ(std::any_cast<int>(s1.second->extra), 1);
  EXPECT_EQ(s1.pair_index, 0);
  const std::map<int, SegmentTrack> after_first = pipeline.tracks();
  const Result first_result = *s1.result;
  SequenceStep s2 = pipeline.push(syntheticFrame(2, 10.066));
  ASSERT_EQ(s2.outcome, SequenceStep::Outcome::Solved) << s2.problem;
  EXPECT_EQ(s2.result->start, StartKind::Warm) << s2.result->start_note;
  EXPECT_EQ(s2.pair_index, 1);
  // A segment that continues accumulates its motions; the tracks are exactly the alive segments.
  ASSERT_EQ(pipeline.tracks().size(), s2.result->segments.size());
  int continued = 0;
  for (const Segment& s : s2.result->segments) {
    const SegmentTrack& track = pipeline.tracks().at(s.id);
    const auto before = after_first.find(s.id);
    if (before == after_first.end()) continue;
    ++continued;
    EXPECT_TRUE(track.pose.isApprox(s.transform * before->second.pose, 1e-12));
    EXPECT_EQ(track.first_pair, 0);
    EXPECT_EQ(track.last_pair, 1);
  }
  EXPECT_GE(continued, 3);
  EXPECT_EQ(pipeline.pairsSolved(), 2);
}

TEST(SequencePipeline, ResetsOnStampsGoingBackGapsAndInputChanges) {
  Config config;
  config.outer_iterations = 1;
  SequencePipeline pipeline(config, 0, 0.5);
  pipeline.push(syntheticFrame(0, 10.0));
  EXPECT_EQ(pipeline.push(syntheticFrame(1, 10.0)).outcome, SequenceStep::Outcome::RepeatedStamp);
  SequenceStep back = pipeline.push(syntheticFrame(1, 9.0));
  EXPECT_EQ(back.outcome, SequenceStep::Outcome::Started);
  EXPECT_EQ(back.reset_key, "back");
  SequenceStep gap = pipeline.push(syntheticFrame(2, 9.9));
  EXPECT_EQ(gap.outcome, SequenceStep::Outcome::Started);
  EXPECT_EQ(gap.reset_key, "gap");
  StreamFrame other = syntheticFrame(3, 9.95);
  other.source = "another_camera";
  SequenceStep input = pipeline.push(std::move(other));
  EXPECT_EQ(input.reset_key, "input");
  EXPECT_EQ(pipeline.resets(), 3);
  StreamFrame next = syntheticFrame(4, 10.0);
  next.source = "another_camera";
  EXPECT_EQ(pipeline.push(std::move(next)).outcome, SequenceStep::Outcome::Solved);
}

TEST(SequencePipeline, AFailedPairKeepsTheStreamGoingWithoutAPrior) {
  Config config;
  config.outer_iterations = 1;
  SequencePipeline pipeline(config, 0, 0.5);
  pipeline.push(syntheticFrame(0, 1.0));
  ASSERT_EQ(pipeline.push(syntheticFrame(1, 1.03)).outcome, SequenceStep::Outcome::Solved);
  // A frame whose depth is all beyond max_depth: the pair it closes is solved (nothing of frame 1 is found
  // in it), the pair it opens fails (no depth in its frame 1); the stream then goes on cold.
  StreamFrame far = syntheticFrame(2, 1.06);
  for (float& z : far.frame.depth.data) z = 9.f;
  SequenceStep closing = pipeline.push(std::move(far));
  EXPECT_EQ(closing.outcome, SequenceStep::Outcome::Solved) << closing.problem;
  SequenceStep after = pipeline.push(syntheticFrame(3, 1.09));
  EXPECT_EQ(after.outcome, SequenceStep::Outcome::PairFailed);
  EXPECT_NE(after.problem.find("no depth within"), std::string::npos) << after.problem;
  SequenceStep recovered = pipeline.push(syntheticFrame(4, 1.12));
  ASSERT_EQ(recovered.outcome, SequenceStep::Outcome::Solved) << recovered.problem;
  EXPECT_EQ(recovered.result->start, StartKind::Cold);
  // Unusable frames are refused before they enter the sequence.
  StreamFrame bad = syntheticFrame(5, 1.15);
  bad.K.fx = -1;
  EXPECT_THROW(pipeline.push(std::move(bad)), InputError);
  StreamFrame no_depth = syntheticFrame(5, 1.15);
  for (float& z : no_depth.frame.depth.data) z = 0.f;
  EXPECT_THROW(pipeline.push(std::move(no_depth)), InputError);
  EXPECT_EQ(pipeline.push(syntheticFrame(5, 1.15)).outcome, SequenceStep::Outcome::Solved);
}

TEST(SequencePipeline, RejectsBadSettings) {
  Config config;
  EXPECT_THROW(SequencePipeline(config, 3, 1.0), ConfigError);
  EXPECT_THROW(SequencePipeline(config, 0, 0.0), ConfigError);
  EXPECT_THROW(SequencePipeline(config, 0, std::nan("")), ConfigError);
}

}  // namespace
}  // namespace mc_flow
