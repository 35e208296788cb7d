/**
 * @file fault_injection.h
 * @brief Tests and benchmarks only (the mc_flow_testing library, linked by no shipped library or tool): a SolveBackend
 * that forwards every stage to another one and fails once, in the middle of a chosen solve, the way a GPU fault
 * surfaces (BackendError out of a stage). SequencePipeline and the nodelet take such a backend through a
 * SolveBackendFactory (faultOnFirstBackend), so that their GPU-fault path is driven on any machine: the core tests
 * directly, the rostests through a test host of the nodelet (test/ros/nodelet_with_fault.cpp), the soak benchmark
 * through --fault. docs/TESTING.md, "GPU faults".
 */
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "mc_flow/core/sequence.h"

namespace mc_flow {

class SolveBackend;

/// @brief Where an injected fault strikes and what it does there.
struct BackendFault {
  /// The backend's solve it strikes in, 1-based, counted by its buildPyramids calls (one per solve attempt).
  long solve = 1;
  /// The first call of this stage within that solve fails (a name of backendFaultStages()).
  std::string stage = "labelStep";
  /// What happens in place of the stage call: empty = throw BackendError("injected fault: ..."). Another action
  /// may make a real fault (a CUDA test poisons the context) and return; the stage then runs into it.
  std::function<void(const std::string& stage)> action;
};

/// @brief The stage names a BackendFault can name: every SolveBackend and LabelStore operation.
const std::vector<std::string>& backendFaultStages();

/// @brief `backend` with `fault` injected (the fault strikes once). Throws ConfigError for solve < 1, an unknown
/// stage or a null backend.
std::unique_ptr<SolveBackend> withBackendFault(std::unique_ptr<SolveBackend> backend, BackendFault fault);

/// @brief Parses "SOLVE", "SOLVE:STAGE" (e.g. "3" or "3:motionAccumulator": a BackendError there) or
/// "SOLVE:STAGE:hold=MS" (that stage waits MS milliseconds once, then runs: a deliberately slow solve); throws
/// ConfigError naming the text.
BackendFault parseBackendFault(const std::string& text);

/// @brief A SolveBackendFactory whose first backend (makeSolveBackend on CUDA device `cuda_device`) gets `fault`; the
/// later ones (new parameters, the CPU after the fault) are plain. Throws ConfigError for a fault withBackendFault
/// refuses.
SolveBackendFactory faultOnFirstBackend(BackendFault fault, int cuda_device = 0);

}  // namespace mc_flow
