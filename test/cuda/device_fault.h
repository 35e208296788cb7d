// A real CUDA fault for the GPU-fault tests (test/cuda/device_fault.cu).
#pragma once

#include <string>

namespace mc_flow {
namespace test {

/// @brief Launches a kernel that writes through a null device pointer and waits for it: the context then holds
/// the sticky error (cudaErrorIllegalAddress) that a faulting kernel of the backend would leave, and every later
/// CUDA call of this process fails. Returns the CUDA error name the wait reported.
std::string poisonCudaContext();

}  // namespace test
}  // namespace mc_flow
