// Internal helpers of the CUDA backend: error checks that throw, and a device buffer that only grows.
// Included by cuda/*.cu only (needs the CUDA runtime headers).
#pragma once

#include <cuda_runtime.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>

#include "mc_flow/core/error.h"

namespace mc_flow {
namespace cuda_detail {

/// Kernel launches of this process (every launch site checks with MCFLOW_CUDA_CHECK_LAUNCH, which counts it;
/// a CUB algorithm call counts as one, MCFLOW_CUDA_CHECK_CUB), and the device and page-locked allocations
/// of the grow-only buffers, the carries' uploads, and the CUDA graphs captured and instantiated. Read by
/// cudaCounters().
inline std::atomic<std::uint64_t> kernel_launches{0}, device_allocations{0}, pinned_allocations{0}, host_waits{0},
    carry_bytes_uploaded{0}, graph_instantiations{0};

/// @brief Throws BackendError naming the call, the place and the CUDA error when `status` is not cudaSuccess.
inline void check(cudaError_t status, const char* what, const char* file, int line) {
  if (status == cudaSuccess) return;
  throw BackendError(std::string("CUDA error in ") + what + " at " + file + ":" + std::to_string(line) + ": " +
                     cudaGetErrorName(status) + " (" + std::to_string(int(status)) +
                     "): " + cudaGetErrorString(status));
}

/// @brief Device memory of T that is reallocated only when a larger size is requested.
template <typename T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  ~DeviceBuffer() {
    if (data_) cudaFree(data_);  // no throwing from a destructor; a failure here leaves nothing to recover
  }

  /// @brief Makes room for at least `count` elements; old contents are lost when it grows.
  void reserve(std::size_t count) {
    if (count <= capacity_) return;
    if (data_) check(cudaFree(data_), "cudaFree", __FILE__, __LINE__);
    data_ = nullptr;
    capacity_ = 0;
    check(cudaMalloc(reinterpret_cast<void**>(&data_), count * sizeof(T)), "cudaMalloc", __FILE__, __LINE__);
    device_allocations.fetch_add(1, std::memory_order_relaxed);
    capacity_ = count;
  }
  T* get() { return data_; }
  const T* get() const { return data_; }
  std::size_t capacity() const { return capacity_; }

 private:
  T* data_ = nullptr;
  std::size_t capacity_ = 0;
};

}  // namespace cuda_detail
}  // namespace mc_flow

/// Checks a CUDA runtime call; throws mc_flow::BackendError with the CUDA error string.
#define MCFLOW_CUDA_CHECK(call) ::mc_flow::cuda_detail::check((call), #call, __FILE__, __LINE__)
/// Checks the launch of the kernel just enqueued (configuration errors, missing kernel image).
#define MCFLOW_CUDA_CHECK_LAUNCH(kernel_name)                                       \
  (::mc_flow::cuda_detail::kernel_launches.fetch_add(1, std::memory_order_relaxed), \
   ::mc_flow::cuda_detail::check(cudaGetLastError(), "launch of " kernel_name, __FILE__, __LINE__))
/// Waits for a stream's work (the host needs its results), counted: each wait is a round trip the solve pays.
#define MCFLOW_CUDA_WAIT(stream)                                               \
  (::mc_flow::cuda_detail::host_waits.fetch_add(1, std::memory_order_relaxed), \
   ::mc_flow::cuda_detail::check(cudaStreamSynchronize(stream), "cudaStreamSynchronize", __FILE__, __LINE__))
/// Checks a CUB device algorithm call that launches kernels (counted as one launch).
#define MCFLOW_CUDA_CHECK_CUB(call)                                                 \
  (::mc_flow::cuda_detail::kernel_launches.fetch_add(1, std::memory_order_relaxed), \
   ::mc_flow::cuda_detail::check((call), #call, __FILE__, __LINE__))

namespace mc_flow {
namespace cuda_detail {

/// Page-locked host memory of T that only grows: the staging of the small per-call uploads and downloads.
template <typename T>
class PinnedBuffer {
 public:
  PinnedBuffer() = default;
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;
  ~PinnedBuffer() {
    if (data_) cudaFreeHost(data_);
  }
  /// @brief Makes room for at least `count` elements (at least one); old contents are lost when it grows.
  T* reserve(std::size_t count) {
    count = count > 0 ? count : 1;
    if (count <= capacity_) return data_;
    if (data_) MCFLOW_CUDA_CHECK(cudaFreeHost(data_));
    data_ = nullptr;
    capacity_ = 0;
    MCFLOW_CUDA_CHECK(cudaMallocHost(reinterpret_cast<void**>(&data_), count * sizeof(T)));
    pinned_allocations.fetch_add(1, std::memory_order_relaxed);
    capacity_ = count;
    return data_;
  }
  T* get() { return data_; }

 private:
  T* data_ = nullptr;
  std::size_t capacity_ = 0;
};

/// Owns one non-blocking CUDA stream; destroyed without throwing.
struct StreamHolder {
  cudaStream_t stream = nullptr;
  StreamHolder() { MCFLOW_CUDA_CHECK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking)); }
  ~StreamHolder() {
    if (stream) cudaStreamDestroy(stream);
  }
  StreamHolder(const StreamHolder&) = delete;
  StreamHolder& operator=(const StreamHolder&) = delete;
};

/// Owns one CUDA event without timing (marks when a copy out of a staging buffer has finished); destroyed without
/// throwing.
struct EventHolder {
  cudaEvent_t event = nullptr;
  bool recorded = false;
  EventHolder() { MCFLOW_CUDA_CHECK(cudaEventCreateWithFlags(&event, cudaEventDisableTiming)); }
  ~EventHolder() {
    if (event) cudaEventDestroy(event);
  }
  EventHolder(const EventHolder&) = delete;
  EventHolder& operator=(const EventHolder&) = delete;
};

}  // namespace cuda_detail
}  // namespace mc_flow
