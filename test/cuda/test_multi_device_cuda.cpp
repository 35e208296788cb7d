// Several cameras on several GPUs (Config::cuda_device): each solver solves on the device it is given, touches no
// other, and gives what one solver alone on device 0 gives, bit for bit. On a machine with one GPU both solvers run on
// device 0 (the same code and checks); the test that a solver allocates nothing on the other device needs two GPUs and
// skips, saying so, on one.
#include <gtest/gtest.h>

#include "mc_flow/testing/same_result.h"
#include "skip_without_gpu.h"

#include <cstddef>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "core/stream_frames.h"
#include "device_memory.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace mc_flow {
namespace {

constexpr int kFrames = 5;  // 4 pairs: one cold, then warm starts from the previous pair's result

Config cudaConfig(int device) {
  Config config;
  config.backend = Backend::Cuda;
  config.cuda_device = device;
  return config;
}

// Every solved pair's result of synthetic stream `variant` (160x120, with its events) through a SequencePipeline on
// CUDA device `device`; `error` gets what went wrong, so that the stream may run on a thread of its own.
std::vector<Result> solveStream(int variant, int device, std::string& error) {
  std::vector<Result> results;
  try {
    SequencePipeline pipeline(cudaConfig(device), 1, 0.5);
    if (!pipeline.backendUnavailable().empty()) throw BackendError(pipeline.backendUnavailable());
    for (int t = 0; t < kFrames; ++t) {
      const SequenceStep step = pipeline.push(test::syntheticStreamFrame(t, 10.0 + 0.033 * t, variant));
      if (step.outcome == SequenceStep::Outcome::PairFailed)
        throw std::runtime_error("frame " + std::to_string(t) + ": " + step.problem);
      if (step.outcome == SequenceStep::Outcome::Solved) results.push_back(*step.result);
    }
  } catch (const std::exception& e) {
    error = e.what();
  }
  return results;
}

void expectSameStream(const std::vector<Result>& actual, const std::vector<Result>& expected, const std::string& what) {
  ASSERT_EQ(actual.size(), expected.size()) << what;
  for (std::size_t k = 0; k < actual.size(); ++k) {
    SCOPED_TRACE(what + ", pair " + std::to_string(k));
    const Result &a = actual[k], &e = expected[k];
    EXPECT_EQ(a.backend_kind, Backend::Cuda);
    EXPECT_EQ(a.start, e.start);
    EXPECT_EQ(firstDifference(a, e), "");
  }
}

// Two cameras, two GPUs: two pipelines on devices 0 and 1 (both on 0 with one GPU) in two threads, each on a different
// stream with warm starts, give what each stream gives solved alone on device 0, bit for bit.
TEST(MultiDevice, TwoStreamsOnTwoDevicesMatchEachAloneOnDevice0BitForBit) {
  SKIP_WITHOUT_GPU();
  const int devices = test::cudaDeviceCount();
  const int second = devices >= 2 ? 1 : 0;
  std::printf("[   INFO   ] %d CUDA device(s): the two streams run on devices 0 and %d\n", devices, second);
  std::string error;
  const std::vector<Result> alone_a = solveStream(1, 0, error);
  ASSERT_TRUE(error.empty()) << error;
  const std::vector<Result> alone_b = solveStream(2, 0, error);
  ASSERT_TRUE(error.empty()) << error;
  ASSERT_EQ(alone_a.size(), std::size_t(kFrames - 1));
  EXPECT_EQ(alone_a.back().start, StartKind::Warm) << "the stream is to test warm starts too";

  std::vector<Result> together_a, together_b;
  std::string error_a, error_b;
  std::thread thread_a([&] { together_a = solveStream(1, 0, error_a); });
  std::thread thread_b([&] { together_b = solveStream(2, second, error_b); });
  thread_a.join();
  thread_b.join();
  ASSERT_TRUE(error_a.empty()) << error_a;
  ASSERT_TRUE(error_b.empty()) << error_b;
  EXPECT_NE(together_b.front().backend_note.find("device " + std::to_string(second)), std::string::npos)
      << together_b.front().backend_note;
  expectSameStream(together_a, alone_a, "stream 1 on device 0");
  expectSameStream(together_b, alone_b, "stream 2 on device " + std::to_string(second));
}

// A solver on one device allocates nothing on the other: the other device's memory in use (cudaMemGetInfo, all
// processes) is the same before and after a solver is made there and has solved, while its own device's grew. The
// solves run on a thread of their own, so this thread's current device stays as it was.
TEST(MultiDevice, ASolverAllocatesNothingOnTheOtherDevice) {
  SKIP_WITHOUT_GPU();
  const int devices = test::cudaDeviceCount();
  if (devices < 2)
    GTEST_SKIP() << "needs two CUDA devices, " << devices << " present: nothing to check that a solver leaves alone";
  SyntheticSceneOptions options;
  options.width = 640;
  options.height = 480;
  const SyntheticPair pair = renderSyntheticPair(options);
  for (const auto& [own, other] : {std::pair<int, int>{0, 1}, std::pair<int, int>{1, 0}}) {
    SCOPED_TRACE("solver on device " + std::to_string(own) + ", watching device " + std::to_string(other));
    std::size_t other_before = 0, other_after = 0, own_before = 0, own_after = 0;
    // The first question creates the device's primary context if this process has none there yet: ask twice.
    ASSERT_TRUE(test::deviceMemoryInUse(other, &other_before));
    ASSERT_TRUE(test::deviceMemoryInUse(own, &own_before));
    ASSERT_TRUE(test::deviceMemoryInUse(other, &other_before));
    ASSERT_TRUE(test::deviceMemoryInUse(own, &own_before));
    const CudaCounters counters_before = cudaCounters();
    std::unique_ptr<Solver> solver;
    Result result;
    std::string error;
    std::thread solving([&, own = own] {
      try {
        solver = std::make_unique<Solver>(cudaConfig(own));
        for (int k = 0; k < 2; ++k) result = solver->solve(pair.frame1, pair.frame2, pair.intrinsics);
      } catch (const std::exception& e) {
        error = e.what();
      }
    });
    solving.join();
    ASSERT_TRUE(error.empty()) << error;
    EXPECT_EQ(result.backend_kind, Backend::Cuda);
    ASSERT_TRUE(test::deviceMemoryInUse(other, &other_after));
    ASSERT_TRUE(test::deviceMemoryInUse(own, &own_after));
    std::printf("[   INFO   ] solver on device %d: device %d's memory in use %+lld bytes, device %d's %+lld bytes\n",
                own, own, static_cast<long long>(own_after) - static_cast<long long>(own_before), other,
                static_cast<long long>(other_after) - static_cast<long long>(other_before));
    const CudaCounters counters_after = cudaCounters();
    EXPECT_GT(counters_after.device_allocations, counters_before.device_allocations);
    EXPECT_EQ(other_after, other_before)
        << "the solver on device " << own << " allocated on device " << other << " (it made "
        << counters_after.device_allocations - counters_before.device_allocations << " device and "
        << counters_after.pinned_allocations - counters_before.pinned_allocations
        << " page-locked host allocations; page-locked memory is mapped into every device's address space)";
    EXPECT_GT(own_after, own_before) << "the solver's buffers do not show on its own device: the measurement sees "
                                        "nothing, so its other half proves nothing";
    solver.reset();
  }
}

// A cuda_device that does not exist: the CUDA backend's error names the device and the device count; a pipeline (the
// nodelet's, run-seq's) solves on the CPU instead and says why in backendUnavailable() and every result's note.
TEST(MultiDevice, AMissingDeviceIsNamedWithTheDeviceCountAndThePipelineFallsBackToTheCpu) {
  SKIP_WITHOUT_GPU();
  const int devices = test::cudaDeviceCount();
  ASSERT_GE(devices, 1);
  const std::string count_text =
      std::to_string(devices) + " CUDA device" + (devices == 1 ? " is" : "s are") + " present";
  const std::string device_text = "CUDA device " + std::to_string(devices) + " requested (cuda_device)";
  try {
    makeSolveBackend(Backend::Cuda, nullptr, devices);
    ADD_FAILURE() << "cuda_device " << devices << " was accepted with " << devices << " device(s)";
  } catch (const BackendError& e) {
    EXPECT_NE(std::string(e.what()).find(device_text), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(count_text), std::string::npos) << e.what();
  }
  EXPECT_THROW(Solver{cudaConfig(devices)}, BackendError);

  SequencePipeline pipeline(cudaConfig(devices), 1, 0.5);
  EXPECT_EQ(pipeline.solver().backendKind(), Backend::Cpu);
  EXPECT_NE(pipeline.backendUnavailable().find(count_text), std::string::npos) << pipeline.backendUnavailable();
  pipeline.push(test::syntheticStreamFrame(0, 10.0));
  const SequenceStep step = pipeline.push(test::syntheticStreamFrame(1, 10.033));
  ASSERT_EQ(step.outcome, SequenceStep::Outcome::Solved) << step.problem;
  EXPECT_EQ(step.result->backend_kind, Backend::Cpu);
  EXPECT_EQ(step.result->backend_note, "cpu (fallback: " + pipeline.backendUnavailable() + ")");
  EXPECT_NE(step.result->backend_note.find(device_text), std::string::npos) << step.result->backend_note;
  EXPECT_TRUE(step.backend_fallback.empty()) << "no GPU failed at run time: no pair is skipped";
}

}  // namespace
}  // namespace mc_flow
