// The CUDA runtime's view of the devices, for the multi-device tests (test/cuda/device_memory.cu); where the build
// has no CUDA, no device and no answer.
#pragma once

#include <cstddef>

namespace mc_flow {
namespace test {

#ifdef MCFLOW_HAVE_CUDA
/// @brief cudaGetDeviceCount, 0 where it fails (no driver).
int cudaDeviceCount();
/// @brief Device memory in use on CUDA device `device` by all processes (cudaMemGetInfo) [bytes]; false where it cannot
/// be asked. The calling thread's current device is restored. The first question creates the device's primary context
/// (hundreds of MB): ask once before the reading that a measurement starts from.
bool deviceMemoryInUse(int device, std::size_t* used);
#else
inline int cudaDeviceCount() { return 0; }
inline bool deviceMemoryInUse(int, std::size_t*) { return false; }
#endif

}  // namespace test
}  // namespace mc_flow
