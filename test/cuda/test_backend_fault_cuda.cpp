// GPU faults in the middle of a stream on the real CUDA backend (test/core/test_backend_fault.cpp does the
// same on any machine with an injected fault). A fault thrown out of a CUDA stage, and a real kernel fault that
// poisons the CUDA context, each move the stream to the CPU once; the stream goes on there.
#include <gtest/gtest.h>

#include "skip_without_gpu.h"

#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/testing/fault_injection.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/solver.h"
#include "fault_stream.h"
#ifdef MCFLOW_HAVE_CUDA
#include "device_fault.h"
#endif

namespace mc_flow {
namespace {

constexpr int kWidth = 160, kHeight = 120, kFrames = 7;

// A pipeline on the CUDA backend whose first backend gets `fault`; `requested` logs the factory's calls.
SequencePipeline faultingPipeline(const BackendFault& fault, std::vector<Backend>& requested) {
  Config config;
  config.backend = Backend::Cuda;
  return SequencePipeline(config, 1, 0.5, [fault, &requested](Backend backend, std::string* note) {
    requested.push_back(backend);
    *note = "test";
    return backend == Backend::Cuda ? withBackendFault(makeCudaSolveBackend(), fault) : makeCpuSolveBackend();
  });
}

// What a stream with a fault must show, as text (empty when it all holds): solved on CUDA before the fault,
// exactly one fallback whose report contains `expected`, one CPU backend made, every later pair solved there.
std::string checkFallback(const test::StreamRun& run, const std::vector<Backend>& requested,
                          const std::string& expected) {
  std::ostringstream problems;
  const int fault_frame = run.fallbackFrame();
  if (fault_frame < 2) {
    problems << "expected one fallback after a solved pair, got frame " << fault_frame << "\n";
    return problems.str();
  }
  if (run.fallbacks[fault_frame].find(expected) == std::string::npos)
    problems << "the fallback does not say '" << expected << "': " << run.fallbacks[fault_frame] << "\n";
  for (int t = 1; t < fault_frame; ++t)
    if (run.outcomes[t] != SequenceStep::Outcome::Solved || run.backends[t] != Backend::Cuda)
      problems << "frame " << t << " before the fault was not solved on CUDA\n";
  for (int t = fault_frame + 1; t < int(run.outcomes.size()); ++t)
    if (run.outcomes[t] != SequenceStep::Outcome::Solved || run.backends[t] != Backend::Cpu ||
        run.notes[t] != "cpu (fallback: the cuda backend failed)")
      problems << "frame " << t << " after the fault was not solved on the CPU (note '" << run.notes[t] << "')\n";
  if (requested != std::vector<Backend>{Backend::Cuda, Backend::Cpu})
    problems << "the factory was asked for " << requested.size() << " backends, expected CUDA then the CPU\n";
  return problems.str();
}

TEST(BackendFaultCuda, AFaultThrownByACudaStageMovesTheStreamToTheCpuAndLeavesTheGpuUsable) {
  SKIP_WITHOUT_GPU();
  BackendFault fault;
  fault.solve = 3;
  fault.stage = "motionAccumulator";
  std::vector<Backend> requested;
  SequencePipeline pipeline = faultingPipeline(fault, requested);
  const test::StreamRun run = test::runStream(pipeline, kFrames, kWidth, kHeight);
  EXPECT_EQ(checkFallback(run, requested, "injected fault in stage motionAccumulator of solve 3 of the cuda backend"),
            "");
  EXPECT_EQ(pipeline.backendFallbacks(), 1);

  // The CUDA backend was dropped in the middle of a solve: a new one must work.
  const test::StreamRun again = [] {
    Config config;
    config.backend = Backend::Cuda;
    SequencePipeline fresh(config, 1, 0.5);
    return test::runStream(fresh, 3, kWidth, kHeight);
  }();
  EXPECT_EQ(again.outcomes[2], SequenceStep::Outcome::Solved);
  EXPECT_EQ(again.backends[2], Backend::Cuda);
}

#ifdef MCFLOW_HAVE_CUDA
// Runs in a child process (a death test): the poisoned context would fail every later test of this process.
void streamIntoARealCudaFault() {
  std::string poisoned;
  BackendFault fault;
  fault.solve = 3;
  fault.stage = "labelStep";
  fault.action = [&poisoned](const std::string&) { poisoned = test::poisonCudaContext(); };
  std::vector<Backend> requested;
  SequencePipeline pipeline = faultingPipeline(fault, requested);
  const test::StreamRun run = test::runStream(pipeline, kFrames, kWidth, kHeight);
  std::string problems = checkFallback(run, requested, "cudaErrorIllegalAddress");
  if (poisoned != "cudaErrorIllegalAddress") problems += "the fault kernel reported " + poisoned + "\n";
  const int frame = run.fallbackFrame();
  std::fprintf(stderr, "fallback at frame %d: %s\n", frame, frame >= 0 ? run.fallbacks[frame].c_str() : "-");
  std::fprintf(stderr, "%s", problems.empty() ? "the stream went on on the CPU\n" : problems.c_str());
  std::exit(problems.empty() ? 0 : 1);
}

TEST(BackendFaultCuda, ARealKernelFaultMidStreamMovesTheStreamToTheCpu) {
  SKIP_WITHOUT_GPU();
  // A fresh process (fork + exec), with a CUDA context of its own.
#ifdef GTEST_FLAG_SET
  GTEST_FLAG_SET(death_test_style, "threadsafe");
#else
  ::testing::GTEST_FLAG(death_test_style) = "threadsafe";
#endif
  // The backend's own check reports the sticky error of the faulted kernel: "CUDA error in ... at ...:
  // cudaErrorIllegalAddress (700): an illegal memory access was encountered".
  EXPECT_EXIT(streamIntoARealCudaFault(), ::testing::ExitedWithCode(0),
              "CUDA error in .*cudaErrorIllegalAddress.*\nthe stream went on on the CPU");
}
#endif

}  // namespace
}  // namespace mc_flow
