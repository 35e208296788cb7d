// The ROS-free stream pipeline: preprocessing rule, pairing and resets, warm starts, tracks.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/testing/fault_injection.h"
#include "mc_flow/testing/same_result.h"
#include "mc_flow/core/sequence.h"
#include "stream_frames.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/warm_start.h"
#include "mc_flow/eval/synthetic_scene.h"

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

using test::syntheticStreamFrame;

TEST(SequencePipeline, PairsFramesWarmStartsAndTracksSegments) {
  Config config;
  SequencePipeline pipeline(config, 0, 0.5);
  SequenceStep s0 = pipeline.push(syntheticStreamFrame(0, 10.0));
  EXPECT_EQ(s0.outcome, SequenceStep::Outcome::Started);
  EXPECT_TRUE(s0.reset_key.empty());
  SequenceStep s1 = pipeline.push(syntheticStreamFrame(1, 10.033));
  ASSERT_EQ(s1.outcome, SequenceStep::Outcome::Solved) << s1.problem;
  EXPECT_EQ(s1.result->start, StartKind::Cold);
  EXPECT_EQ(std::any_cast<int>(s1.first->extra), 0);
  EXPECT_EQ(std::any_cast<int>(s1.second->extra), 1);
  EXPECT_EQ(s1.pair_index, 0);
  const std::map<int, SegmentTrack> after_first = pipeline.tracks();
  const Result first_result = *s1.result;
  SequenceStep s2 = pipeline.push(syntheticStreamFrame(2, 10.066));
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

// Outputs nobody asked for (the nodelet asks per pair by its subscribers): the soft labels and the scene flow stay 0x0,
// and the stream goes on as with them (the warm start needs only the labels, optical flow and moved depth), bit for
// bit; asked for again, they come back.
TEST(SequencePipeline, OutputsNotSelectedStayEmptyAndTheStreamIsTheSame) {
  Config config;
  SequencePipeline with(config, 0, 0.5), without(config, 0, 0.5);
  OutputSelection none;
  none.soft_labels = none.scene_flow = false;
  without.setOutputs(none);
  for (int t = 0; t < 4; ++t) {
    const double stamp = 10.0 + 0.033 * t;
    if (t == 3) without.setOutputs(OutputSelection());
    const SequenceStep a = with.push(syntheticStreamFrame(t, stamp)), b = without.push(syntheticStreamFrame(t, stamp));
    if (t == 0) continue;
    ASSERT_EQ(a.outcome, SequenceStep::Outcome::Solved) << a.problem;
    ASSERT_EQ(b.outcome, SequenceStep::Outcome::Solved) << b.problem;
    SCOPED_TRACE("pair " + std::to_string(t));
    EXPECT_EQ(b.result->start, a.result->start);
    if (t >= 2) EXPECT_EQ(b.result->start, StartKind::Warm) << b.result->start_note;
    if (t == 3) {
      EXPECT_EQ(firstDifference(*a.result, *b.result), "");
      continue;
    }
    EXPECT_EQ(b.result->soft_labels.width, 0);
    EXPECT_EQ(b.result->soft_labels.count, 0);
    EXPECT_TRUE(b.result->soft_labels.data.empty());
    EXPECT_EQ(b.result->scene_flow.width, 0);
    EXPECT_TRUE(b.result->scene_flow.data.empty());
    Result a_without = *a.result;  // everything else byte for byte (NaN where depth is missing included)
    a_without.soft_labels = SoftLabels();
    a_without.scene_flow = ImageF();
    EXPECT_EQ(firstDifference(a_without, *b.result), "");
  }
}

TEST(SequencePipeline, ResetsOnStampsGoingBackGapsAndInputChanges) {
  Config config;
  config.outer_iterations = 1;
  SequencePipeline pipeline(config, 0, 0.5);
  pipeline.push(syntheticStreamFrame(0, 10.0));
  EXPECT_EQ(pipeline.push(syntheticStreamFrame(1, 10.0)).outcome, SequenceStep::Outcome::RepeatedStamp);
  SequenceStep back = pipeline.push(syntheticStreamFrame(1, 9.0));
  EXPECT_EQ(back.outcome, SequenceStep::Outcome::Started);
  EXPECT_EQ(back.reset_key, "back");
  SequenceStep gap = pipeline.push(syntheticStreamFrame(2, 9.9));
  EXPECT_EQ(gap.outcome, SequenceStep::Outcome::Started);
  EXPECT_EQ(gap.reset_key, "gap");
  StreamFrame other = syntheticStreamFrame(3, 9.95);
  other.source = "another_camera";
  SequenceStep input = pipeline.push(std::move(other));
  EXPECT_EQ(input.reset_key, "input");
  EXPECT_EQ(pipeline.resets(), 3);
  StreamFrame next = syntheticStreamFrame(4, 10.0);
  next.source = "another_camera";
  EXPECT_EQ(pipeline.push(std::move(next)).outcome, SequenceStep::Outcome::Solved);
}

TEST(SequencePipeline, AFailedPairKeepsTheStreamGoingWithoutAPrior) {
  Config config;
  config.outer_iterations = 1;
  SequencePipeline pipeline(config, 0, 0.5);
  pipeline.push(syntheticStreamFrame(0, 1.0));
  ASSERT_EQ(pipeline.push(syntheticStreamFrame(1, 1.03)).outcome, SequenceStep::Outcome::Solved);
  // A frame whose depth is all beyond max_depth: the pair it closes is solved (nothing of frame 1 is found
  // in it), the pair it opens fails (no depth in its frame 1); the stream then goes on cold.
  StreamFrame far = syntheticStreamFrame(2, 1.06);
  for (float& z : far.frame.depth.data) z = 9.f;
  SequenceStep closing = pipeline.push(std::move(far));
  EXPECT_EQ(closing.outcome, SequenceStep::Outcome::Solved) << closing.problem;
  SequenceStep after = pipeline.push(syntheticStreamFrame(3, 1.09));
  EXPECT_EQ(after.outcome, SequenceStep::Outcome::PairFailed);
  EXPECT_NE(after.problem.find("no depth within"), std::string::npos) << after.problem;
  SequenceStep recovered = pipeline.push(syntheticStreamFrame(4, 1.12));
  ASSERT_EQ(recovered.outcome, SequenceStep::Outcome::Solved) << recovered.problem;
  EXPECT_EQ(recovered.result->start, StartKind::Cold);
  // Unusable frames are refused before they enter the sequence.
  StreamFrame bad = syntheticStreamFrame(5, 1.15);
  bad.K.fx = -1;
  EXPECT_THROW(pipeline.push(std::move(bad)), InputError);
  StreamFrame no_depth = syntheticStreamFrame(5, 1.15);
  for (float& z : no_depth.frame.depth.data) z = 0.f;
  EXPECT_THROW(pipeline.push(std::move(no_depth)), InputError);
  EXPECT_EQ(pipeline.push(syntheticStreamFrame(5, 1.15)).outcome, SequenceStep::Outcome::Solved);
}

// Every id a solved pair hands out: its segments and the ids it reports as merged, ended, revived or dormant.
std::set<int> idsOf(const Result& r) {
  std::set<int> ids;
  for (const Segment& s : r.segments) ids.insert(s.id);
  for (const auto& [id, into] : r.merged_ids) ids.insert({id, into});
  ids.insert(r.ended_ids.begin(), r.ended_ids.end());
  ids.insert(r.revived_ids.begin(), r.revived_ids.end());
  for (const auto& [id, age] : r.dormant_ids) ids.insert(id);
  return ids;
}

// A pair solved without a prior (first of a sequence after a reset, or after a failed pair): its ids are all
// above every earlier id, its labels carry them, and every track starts at this pair.
void expectFreshIds(const SequencePipeline& pipeline, const SequenceStep& step, int highest_before) {
  ASSERT_EQ(step.outcome, SequenceStep::Outcome::Solved) << step.problem;
  const Result& r = *step.result;
  EXPECT_EQ(r.start, StartKind::Cold);
  ASSERT_FALSE(r.segments.empty());
  std::set<int> segment_ids;
  for (const Segment& s : r.segments) {
    EXPECT_GT(s.id, highest_before) << "pair " << step.pair_index << " reuses an earlier id";
    segment_ids.insert(s.id);
    const SegmentTrack& track = pipeline.tracks().at(s.id);
    EXPECT_EQ(track.first_pair, step.pair_index) << "id " << s.id << " continues an earlier track";
    EXPECT_TRUE(track.pose.isApprox(s.transform, 1e-12));
  }
  EXPECT_EQ(pipeline.tracks().size(), r.segments.size());
  EXPECT_GT(r.next_id, *segment_ids.rbegin());
  EXPECT_EQ(pipeline.nextId(), r.next_id);
  for (int label : r.labels.data)
    if (label != 0) EXPECT_TRUE(segment_ids.count(label)) << "label " << label << " is no segment's id";
}

TEST(SequencePipeline, IdsAfterAResetStartAboveEveryEarlierId) {
  Config config;
  config.outer_iterations = 2;
  SequencePipeline pipeline(config, 0, 0.5);
  int highest = 0;
  pipeline.push(syntheticStreamFrame(0, 1.0));
  for (int t = 1; t <= 3; ++t) {
    SequenceStep step = pipeline.push(syntheticStreamFrame(t, 1.0 + 0.033 * t));
    ASSERT_EQ(step.outcome, SequenceStep::Outcome::Solved) << step.problem;
    for (int id : idsOf(*step.result)) highest = std::max(highest, id);
    highest = std::max(highest, step.result->next_id - 1);
  }
  ASSERT_GE(highest, 3);
  const int before_reset = highest;

  // The stamps go back (a bag looping): a new sequence whose segments take none of the earlier ids.
  EXPECT_EQ(pipeline.push(syntheticStreamFrame(0, 0.5)).reset_key, "back");
  SequenceStep cold = pipeline.push(syntheticStreamFrame(1, 0.533));
  expectFreshIds(pipeline, cold, before_reset);
  EXPECT_TRUE(cold.result->merged_ids.empty() && cold.result->ended_ids.empty() && cold.result->dormant_ids.empty());
  // The sequence goes on warm from the renumbered result: its ids continue and new ones come after them.
  SequenceStep warm = pipeline.push(syntheticStreamFrame(2, 0.566));
  ASSERT_EQ(warm.outcome, SequenceStep::Outcome::Solved) << warm.problem;
  EXPECT_EQ(warm.result->start, StartKind::Warm) << warm.result->start_note;
  int continued = 0;
  for (const Segment& s : warm.result->segments) {
    EXPECT_GT(s.id, before_reset);
    if (pipeline.tracks().at(s.id).first_pair == cold.pair_index) ++continued;
  }
  EXPECT_GE(continued, 3) << "the warm pair after the reset continues the cold pair's ids";
  for (int id : idsOf(*warm.result)) highest = std::max(highest, id);
  highest = std::max(highest, warm.result->next_id - 1);

  // A gap resets again: above both earlier sequences.
  EXPECT_EQ(pipeline.push(syntheticStreamFrame(3, 5.0)).reset_key, "gap");
  expectFreshIds(pipeline, pipeline.push(syntheticStreamFrame(4, 5.033)), highest);
}

TEST(SequencePipeline, APairAfterAFailedOneContinuesNoEarlierTrack) {
  Config config;
  config.outer_iterations = 1;
  config.backend = Backend::Cuda;  // the factory stands in for a CUDA backend whose second solve fails
  BackendFault fault;
  fault.solve = 2;
  SequencePipeline pipeline(config, 0, 0.5, [&](Backend backend, std::string* note) {
    *note = "test";
    std::unique_ptr<SolveBackend> cpu = makeCpuSolveBackend();
    return backend == Backend::Cuda ? withBackendFault(std::move(cpu), fault) : std::move(cpu);
  });
  pipeline.push(syntheticStreamFrame(0, 1.0));
  SequenceStep first = pipeline.push(syntheticStreamFrame(1, 1.033));
  ASSERT_EQ(first.outcome, SequenceStep::Outcome::Solved) << first.problem;
  int highest = 0;
  for (int id : idsOf(*first.result)) highest = std::max(highest, id);
  highest = std::max(highest, first.result->next_id - 1);
  ASSERT_EQ(pipeline.tracks().size(), first.result->segments.size());
  // The failed pair is no reset: the first pair's tracks are still there, and the cold pair after it must not
  // continue them (numbered 1..m again, its segments extended the first pair's poses of ids 1..m).
  SequenceStep failed = pipeline.push(syntheticStreamFrame(2, 1.066));
  ASSERT_EQ(failed.outcome, SequenceStep::Outcome::PairFailed);
  ASSERT_FALSE(failed.backend_fallback.empty());
  EXPECT_EQ(pipeline.resets(), 0);
  expectFreshIds(pipeline, pipeline.push(syntheticStreamFrame(3, 1.099)), highest);
}

// backend=cuda where it cannot be made (no GPU here, or a cuda_device that does not exist on a GPU machine): the
// pipeline solves on the CPU rather than not at all, and says why (the nodelet's one warning and run-seq's print it).
TEST(SequencePipeline, ABackendThatCannotBeMadeFallsBackToTheCpuSayingWhy) {
  Config config;
  config.outer_iterations = 1;
  config.backend = Backend::Cuda;
  config.cuda_device = 63;  // Config's largest: no machine has 64 GPUs
  std::string why;
  ASSERT_FALSE(cudaBackendAvailable(&why, config.cuda_device));
  SequencePipeline pipeline(config, 0, 0.5);
  EXPECT_EQ(pipeline.solver().backendKind(), Backend::Cpu);
  EXPECT_EQ(pipeline.backendUnavailable(), "CUDA backend requested but unavailable: " + why);
  pipeline.push(syntheticStreamFrame(0, 1.0));
  const SequenceStep step = pipeline.push(syntheticStreamFrame(1, 1.033));
  ASSERT_EQ(step.outcome, SequenceStep::Outcome::Solved) << step.problem;
  EXPECT_EQ(step.result->backend_kind, Backend::Cpu);
  EXPECT_EQ(step.result->backend_note, "cpu (fallback: CUDA backend requested but unavailable: " + why + ")");
  EXPECT_TRUE(step.backend_fallback.empty()) << "nothing failed at run time";
  EXPECT_EQ(pipeline.backendFallbacks(), 0);
  // New parameters that ask for the CPU: made as asked, nothing unavailable.
  Config cpu = config;
  cpu.backend = Backend::Cpu;
  pipeline.setConfig(cpu);
  EXPECT_TRUE(pipeline.backendUnavailable().empty()) << pipeline.backendUnavailable();
  const SequenceStep next = pipeline.push(syntheticStreamFrame(2, 1.066));
  ASSERT_EQ(next.outcome, SequenceStep::Outcome::Solved) << next.problem;
  EXPECT_EQ(next.result->backend_note, "cpu (requested)");
}

// The same through a factory, on any machine: its BackendError's text reaches the note, the CPU backend comes from the
// factory too, a setConfig falls back the same way, and a bad config is still a ConfigError (the solver is kept).
TEST(SequencePipeline, AFactorysBackendErrorGivesACpuSolverAndABadConfigStillThrows) {
  Config config;
  config.outer_iterations = 1;
  config.backend = Backend::Cuda;
  const std::string missing = "CUDA device 7 requested (cuda_device), but 2 CUDA devices are present (0..1)";
  std::vector<Backend> requested;
  SolveBackendFactory factory = [&](Backend backend, std::string* note) -> std::unique_ptr<SolveBackend> {
    requested.push_back(backend);
    if (backend == Backend::Cuda) throw BackendError("CUDA backend requested but unavailable: " + missing);
    *note = "cpu (requested)";
    return makeCpuSolveBackend();
  };
  SequencePipeline pipeline(config, 0, 0.5, factory);
  EXPECT_EQ(requested, (std::vector<Backend>{Backend::Cuda, Backend::Cpu}));
  EXPECT_NE(pipeline.backendUnavailable().find(missing), std::string::npos) << pipeline.backendUnavailable();
  pipeline.push(syntheticStreamFrame(0, 1.0));
  const SequenceStep step = pipeline.push(syntheticStreamFrame(1, 1.033));
  ASSERT_EQ(step.outcome, SequenceStep::Outcome::Solved) << step.problem;
  EXPECT_EQ(step.result->backend_kind, Backend::Cpu);
  EXPECT_EQ(step.result->backend_note, "cpu (fallback: CUDA backend requested but unavailable: " + missing + ")");

  Config bad = config;
  bad.cuda_device = 64;  // outside Config's range: a configuration error, not a backend one
  EXPECT_THROW(pipeline.setConfig(bad), ConfigError);
  EXPECT_THROW(SequencePipeline(bad, 0, 0.5, factory), ConfigError);
  EXPECT_EQ(pipeline.solver().backendKind(), Backend::Cpu) << "the solver is kept";

  // The CPU requested and not to be had: nothing to fall back to.
  Config cpu = config;
  cpu.backend = Backend::Cpu;
  EXPECT_THROW(SequencePipeline(cpu, 0, 0.5,
                                [](Backend, std::string*) -> std::unique_ptr<SolveBackend> {
                                  throw BackendError("no CPU backend");
                                }),
               BackendError);
}

TEST(OffsetSegmentIds, MovesEveryIdOfAResultTogether) {
  Result r;
  r.width = 3;
  r.height = 1;
  r.segments.resize(2);
  r.segments[0].id = 1;
  r.segments[1].id = 2;
  r.labels = ImageI32(3, 1, 1, 0);
  r.labels.data = {1, 0, 2};
  r.dormant_regions = ImageI32(3, 1, 1, 0);
  r.dormant_regions.data = {0, 4, 0};
  r.merged_ids = {{3, 1}};
  r.ended_ids = {5};
  r.revived_ids = {2};
  r.dormant_ids = {{4, 1}};
  r.next_id = 6;
  offsetSegmentIds(r, 11);
  EXPECT_EQ(r.segments[0].id, 11);
  EXPECT_EQ(r.segments[1].id, 12);
  EXPECT_EQ(r.labels.data, (std::vector<int>{11, 0, 12}));
  EXPECT_EQ(r.dormant_regions.data, (std::vector<int>{0, 14, 0}));
  EXPECT_EQ(r.merged_ids, (std::vector<std::pair<int, int>>{{13, 11}}));
  EXPECT_EQ(r.ended_ids, std::vector<int>{15});
  EXPECT_EQ(r.revived_ids, std::vector<int>{12});
  EXPECT_EQ(r.dormant_ids, (std::vector<std::pair<int, int>>{{14, 1}}));
  EXPECT_EQ(r.next_id, 16);
  EXPECT_THROW(offsetSegmentIds(r, 0), InputError);
}

TEST(SequencePipeline, RejectsBadSettings) {
  Config config;
  EXPECT_THROW(SequencePipeline(config, 3, 1.0), ConfigError);
  EXPECT_THROW(SequencePipeline(config, 0, 0.0), ConfigError);
  EXPECT_THROW(SequencePipeline(config, 0, std::nan("")), ConfigError);
}

}  // namespace
}  // namespace mc_flow
