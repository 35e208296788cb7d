// GPU faults in the middle of a stream, on any machine: a backend fault injected through the pipeline's
// SolveBackendFactory (mc_flow/testing/fault_injection.h) moves the stream to the CPU once, and
// the stream goes on there. test/cuda/test_backend_fault_cuda.cpp does the same with a real CUDA fault.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/testing/fault_injection.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "fault_stream.h"

namespace mc_flow {
namespace {

using test::runStream;
using test::StreamRun;

constexpr int kWidth = 96, kHeight = 72;

TEST(BackendFault, AFaultMidStreamMovesTheStreamToTheCpuOnceAndItGoesOn) {
  Config config;
  config.backend = Backend::Cuda;  // what the GPU machine runs; the factory stands in for the CUDA backend
  std::vector<Backend> requested;
  BackendFault fault;
  fault.solve = 3;
  fault.stage = "labelStep";
  SequencePipeline pipeline(config, 1, 0.5, [&](Backend backend, std::string* note) {
    requested.push_back(backend);
    *note = "test";
    std::unique_ptr<SolveBackend> cpu = makeCpuSolveBackend();
    return backend == Backend::Cuda ? withBackendFault(std::move(cpu), fault) : std::move(cpu);
  });
  const StreamRun run = runStream(pipeline, 8, kWidth, kHeight);

  // Frames 1 and 2 are solved (solves 1 and 2; a warm pair that is re-solved cold takes two solves, so the
  // fault may come one pair early, never later than frame 3).
  const int fault_frame = run.fallbackFrame();
  ASSERT_GE(fault_frame, 2) << "exactly one step reports the fallback, after at least one solved pair";
  ASSERT_LE(fault_frame, 3);
  EXPECT_NE(run.fallbacks[fault_frame].find("injected fault in stage labelStep of solve 3"), std::string::npos)
      << run.fallbacks[fault_frame];
  EXPECT_EQ(run.outcomes[fault_frame], SequenceStep::Outcome::PairFailed);
  for (int t = 1; t < fault_frame; ++t) EXPECT_EQ(run.outcomes[t], SequenceStep::Outcome::Solved) << "frame " << t;

  // One fallback, one CPU backend made for it, and every later pair solved there, without a new warning.
  EXPECT_EQ(pipeline.backendFallbacks(), 1);
  EXPECT_EQ(requested, (std::vector<Backend>{Backend::Cuda, Backend::Cpu}));
  EXPECT_EQ(pipeline.solver().config().backend, Backend::Cpu);
  for (int t = fault_frame + 1; t < 8; ++t) {
    EXPECT_EQ(run.outcomes[t], SequenceStep::Outcome::Solved) << "frame " << t;
    EXPECT_TRUE(run.fallbacks[t].empty()) << "frame " << t << ": " << run.fallbacks[t];
    EXPECT_EQ(run.backends[t], Backend::Cpu) << "frame " << t;
    EXPECT_EQ(run.notes[t], "cpu (fallback: the cpu backend failed)") << "frame " << t;
  }
  EXPECT_EQ(run.notes[1], "test");
  // The stream continues from the failed pair's second frame, without a prior, then warm again.
  EXPECT_EQ(run.first_frames[fault_frame + 1], fault_frame);
  EXPECT_EQ(run.starts[fault_frame + 1], StartKind::Cold);
  EXPECT_EQ(run.starts[fault_frame + 2], StartKind::Warm);
}

TEST(BackendFault, FaultOnFirstBackendFaultsThePipelinesFirstBackendOnly) {
  Config config;
  config.backend = Backend::Cpu;
  SequencePipeline pipeline(config, 1, 0.5, faultOnFirstBackend(parseBackendFault("2:motionAccumulator")));
  const StreamRun run = runStream(pipeline, 6, kWidth, kHeight);
  const int fault_frame = run.fallbackFrame();
  ASSERT_GE(fault_frame, 1);
  EXPECT_NE(run.fallbacks[fault_frame].find("injected fault in stage motionAccumulator of solve 2"), std::string::npos)
      << run.fallbacks[fault_frame];
  EXPECT_EQ(pipeline.backendFallbacks(), 1);
  for (int t = fault_frame + 1; t < 6; ++t) EXPECT_EQ(run.outcomes[t], SequenceStep::Outcome::Solved) << "frame " << t;

  // A second pipeline with its own factory faults the same way: the fault belongs to the factory.
  SequencePipeline second(config, 1, 0.5, faultOnFirstBackend(parseBackendFault("2:motionAccumulator")));
  EXPECT_EQ(runStream(second, 6, kWidth, kHeight).fallbackFrame(), fault_frame);
  // Without one, nothing is injected (the product has no hook of its own).
  SequencePipeline plain(config, 1, 0.5);
  EXPECT_EQ(runStream(plain, 6, kWidth, kHeight).fallbackFrame(), -1);
}

TEST(BackendFault, MalformedFaultTextsAreRefusedByName) {
  for (const char* bad : {"x", "0", "-1", "3:", "3:noSuchStage", ":labelStep", "3:labelStep:", "3:labelStep:hold=",
                          "3:labelStep:hold=-5", "3:labelStep:wait=5", "3:noSuchStage:hold=5"}) {
    try {
      parseBackendFault(bad);
      ADD_FAILURE() << "'" << bad << "' was accepted";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("'") + bad + "'"), std::string::npos) << e.what();
    }
  }
  BackendFault unknown;
  unknown.stage = "noSuchStage";
  EXPECT_THROW(faultOnFirstBackend(unknown), ConfigError);
  const BackendFault parsed = parseBackendFault("12:trialCuts");
  EXPECT_EQ(parsed.solve, 12);
  EXPECT_EQ(parsed.stage, "trialCuts");
  EXPECT_EQ(parseBackendFault("4").stage, "labelStep");
  EXPECT_FALSE(parsed.action);  // a fault: the stage throws
  const BackendFault hold = parseBackendFault("2:outputs:hold=30");
  EXPECT_EQ(hold.solve, 2);
  EXPECT_EQ(hold.stage, "outputs");
  ASSERT_TRUE(hold.action);
  const auto before = std::chrono::steady_clock::now();
  hold.action("outputs");  // returns (the stage then runs) after at least the hold
  EXPECT_GE(std::chrono::steady_clock::now() - before, std::chrono::milliseconds(30));
  EXPECT_THROW(withBackendFault(nullptr, BackendFault{}), ConfigError);
}

// The pair and the one-thread CPU config the forwarding tests solve, and a fault whose action records the stages it
// struck instead of throwing.
SyntheticPair forwardingPair() {
  SyntheticSceneOptions o;
  o.width = kWidth;
  o.height = kHeight;
  o.variant = 1;
  return renderSyntheticPair(o);
}

Config oneThreadCpu() {
  Config config;
  config.backend = Backend::Cpu;
  config.threads = 1;
  return config;
}

BackendFault recordingFault(int solve, const std::string& stage, std::vector<std::string>& struck) {
  BackendFault fault;
  fault.solve = solve;
  fault.stage = stage;
  fault.action = [&struck](const std::string& name) { struck.push_back(name); };
  return fault;
}

TEST(BackendFault, TheBatchedPassesAndTheUnionRefitsAreStagesToo) {
  // A cold solve with several segments calls the batched passes, the merge test's pair refits and the world's union
  // fit: a fault named after each strikes there (the CPU backend answers the refits on the host, but the wrapper is
  // asked).
  const SyntheticPair pair = forwardingPair();
  const Config config = oneThreadCpu();
  for (const char* stage : {"costModels", "refitUnionsWhereTheSumsAre", "refitPairsWhereTheSumsAre"}) {
    std::vector<std::string> struck;
    Solver wrapped(config, withBackendFault(makeCpuSolveBackend(), recordingFault(1, stage, struck)), "wrapped");
    wrapped.solve(pair.frame1, pair.frame2, pair.intrinsics);
    EXPECT_EQ(struck, std::vector<std::string>{stage});
  }
}

TEST(BackendFault, TheFaultingBackendForwardsEveryStageUnchanged) {
  // With an action that does not throw, the wrapped backend must give the plain backend's results bit for bit
  // (every stage forwarded with its arguments), and the action runs once, in the named solve.
  const SyntheticPair pair = forwardingPair();
  const Config config = oneThreadCpu();
  std::vector<std::string> struck;
  Solver plain(config);
  Solver wrapped(config, withBackendFault(makeCpuSolveBackend(), recordingFault(2, "remap", struck)), "wrapped");
  for (int solve = 1; solve <= 3; ++solve) {
    const Result a = plain.solve(pair.frame1, pair.frame2, pair.intrinsics);
    const Result b = wrapped.solve(pair.frame1, pair.frame2, pair.intrinsics);
    EXPECT_EQ(struck.size(), solve >= 2 ? 1u : 0u) << "after solve " << solve;
    ASSERT_EQ(a.segments.size(), b.segments.size());
    EXPECT_EQ(a.labels.data, b.labels.data);
    EXPECT_EQ(a.soft_labels.data, b.soft_labels.data);
    EXPECT_EQ(a.energy, b.energy);
    EXPECT_EQ(b.backend_note, "wrapped");
  }
  EXPECT_EQ(struck, std::vector<std::string>{"remap"});
  EXPECT_THROW(Solver(config, nullptr, ""), ConfigError);
}

}  // namespace
}  // namespace mc_flow
