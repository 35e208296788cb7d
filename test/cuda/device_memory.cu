// The CUDA runtime's view of the devices, for test/cuda/test_multi_device_cuda.cpp.
#include "device_memory.h"

#include <cuda_runtime.h>

namespace mc_flow {
namespace test {

int cudaDeviceCount() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    cudaGetLastError();
    return 0;
  }
  return count;
}

bool deviceMemoryInUse(int device, std::size_t* used) {
  int previous = 0;
  if (cudaGetDevice(&previous) != cudaSuccess || cudaSetDevice(device) != cudaSuccess) {
    cudaGetLastError();
    return false;
  }
  std::size_t free_bytes = 0, total_bytes = 0;
  const bool ok = cudaMemGetInfo(&free_bytes, &total_bytes) == cudaSuccess;
  if (!ok) cudaGetLastError();
  cudaSetDevice(previous);
  if (ok && used) *used = total_bytes - free_bytes;
  return ok;
}

}  // namespace test
}  // namespace mc_flow
