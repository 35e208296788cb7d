// A kernel that faults, for test/cuda/test_backend_fault_cuda.cpp.
#include "device_fault.h"

#include <cuda_runtime.h>

namespace mc_flow {
namespace test {

namespace {

__global__ void writeThroughNull(int* target) { *target = 1; }

}  // namespace

std::string poisonCudaContext() {
  writeThroughNull<<<1, 1>>>(nullptr);
  const cudaError_t status = cudaDeviceSynchronize();
  return cudaGetErrorName(status);
}

}  // namespace test
}  // namespace mc_flow
