/**
 * @file solve_backend.h
 * @brief The stages of Algorithm 1 behind one interface, so that the orchestration (src/core/solver.cpp)
 * exists once and each backend keeps the state of a solve where it computes: the CPU backend in host
 * images (src/core/solve_backend.cpp), the CUDA backend in device buffers (cuda/solve_backend.cu) that
 * stay there from the upload of the pyramids to the download of the final labels.
 *
 * The frames go in once (buildPyramids) and the outputs come out once (outputs). In between the host only
 * takes the decisions (which labels merge or split, the Levenberg-Marquardt steps, convergence) from small
 * numbers the backend returns: per-label supports and moments, the normal equations of the motion step,
 * energies, and frame 1's points at the coarse levels K-means and the carried segments need. Design and
 * status: docs/GPU.md, "Stage-level backend".
 */
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "mc_flow/core/config.h"
#include "mc_flow/core/label_adaptation.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/core/warm_start.h"

namespace mc_flow {

/// @brief Which labels the motion step's accumulator sees at a level.
enum class MotionLabels {
  Current,        ///< the solve's soft labels, resampled from the label level to that level
  AllValidAsOne,  ///< one motion label over every valid pixel (the dominant-motion initialisation)
};

/// @brief Result of one label step (data costs, then primal-dual iterations from the warm start).
struct LabelStepStats {
  int iterations = 0;
  double energy = 0;       ///< E(u) of eq. 4 at the end
  double mean_change = 0;  ///< sum over planes of |u_after - u_before|, divided by the pixel count
};

/// @brief The solve's state and stages. One per Solver; not thread-safe.
class SolveBackend : public LabelStore {
 public:
  ~SolveBackend() override = default;
  virtual Backend kind() const = 0;
  /// @brief Makes the calling thread use this backend's device (CUDA: cudaSetDevice; the CPU: nothing). Solver
  /// calls it at the start of every solve, so a Solver may be used from any thread, one thread at a time.
  virtual void activate() {}

  /// @brief Builds both frames' pyramids (`levels` levels, the rules of pyramid.h) where the backend computes:
  /// the CPU backend in host images, the CUDA backend on the device from one upload of each frame. Resets the
  /// labels, the occlusion mask and the dual variables.
  virtual void buildPyramids(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, int levels,
                             const Config& config) = 0;
  /// @brief Frame 1's points (3 channels, NaN where depth is invalid) at `level` in host memory, for the host's
  /// decisions (K-means, carried segments); the CUDA backend downloads a level at its first request in a pair.
  /// Valid until the next buildPyramids.
  virtual const ImageF& framePoints(int level) = 0;
  /// @brief Frame 1's valid pixels (depth within [min_depth, max_depth]) per level.
  virtual const std::vector<int>& validCounts() const = 0;

  /// @brief Hard initial labels at `level` (K-means' assignment or labels carried from the previous pair):
  /// `hard` holds a motion label in [0, motion_labels) per pixel, or -1 for the outlier label; pixels
  /// without depth go to the outlier label whatever `hard` says. Label count = motion_labels + 1.
  virtual void initialiseLabels(int level, const ImageI32& hard, int motion_labels) = 0;
  /// @brief K-means' centres on frame 1's valid points at `level`: kmeansPoints (k-means++ seeding from `seed`, at most
  /// max_iterations Lloyd iterations, stopping when no centre moves further than tolerance_m m); fewer than k where
  /// fewer distinct points exist, none where no point is valid. This default runs kmeansPoints on
  /// framePoints(level); the CUDA backend runs it on the device and downloads only the centres (cuda/kmeans.cu says
  /// where they may differ from the host's).
  virtual std::vector<Eigen::Vector3f> kmeansCentres(int level, int k, int max_iterations, double tolerance_m,
                                                     unsigned seed);
  /// @brief Hard initial labels at `level` from K-means' centres (at least one): each valid point takes its nearest
  /// centre (nearest_centre.h), label count = centres + 1. This default is initialiseLabels of
  /// assignToNearestCentre(framePoints(level), centres); the CUDA backend assigns on the device, without
  /// downloading the level's points.
  virtual void initialiseLabelsFromCentres(int level, const std::vector<Eigen::Vector3f>& centres);
  /// @brief A warm start's hard initial labels at `level`: `hard` (the carried labels, -1 where no carried segment
  /// covers a pixel) with the uncovered valid pixels clustered by kmeansPointList (their points in pixel order,
  /// `clusters` clusters, Config's kmeans_max_iterations, kmeans_tolerance and seed) and numbered from `first_new`,
  /// then initialiseLabels(level, those labels, first_new + the clusters kept). Returns the clusters kept. This default
  /// runs the K-means on framePoints(level); the CUDA backend runs it on the device (the same rules as kmeansCentres'
  /// there), which writes the uncovered pixels' labels, and downloads only its answer.
  virtual int initialiseLabelsWithUncoveredClusters(int level, const ImageI32& hard, int first_new, int clusters,
                                                    const Config& config);
  /// @brief Stream mode (a warm start), right after initialiseLabels: the initial labels below `carried_labels` are the
  /// previous pair's segments. From then on each label step adds Config::warm_switch_cost to every other label's data
  /// cost at the pixels that started in one of them (addSwitchingCost). The carried labels follow remap (merged into
  /// the merged label; removed: none) and moveLabels (nearest pixel); buildPyramids and initialiseLabels clear them.
  virtual void holdCarriedLabels(int carried_labels) = 0;
  /// @brief Stream mode, after buildPyramids: the previous pair's segments carried onto this frame 1
  /// (warm_start.h's CarriedSegments), with the hard labels of `label_level` when it is >= 0. This default runs
  /// warm_start.cpp's carrySegments on the host with `frame1_depth` (the input depth buildPyramids was given) and
  /// framePoints(label_level); the CUDA backend carries on the device from its level-0 depth (the same ids, bit for
  /// bit) and downloads only the carried ids and the level's majority ids. Throws InputError on mismatched sizes.
  virtual CarriedSegments carrySegments(const Result& previous, const ImageF& frame1_depth, int label_level,
                                        const Config& config);
  /// @brief Carries the labels to `level` (up: bilinear and renormalised; down: 2x2 means; the same level:
  /// unchanged), clears the occlusion mask (it is recomputed there) and resets the dual variables.
  virtual void moveLabels(int level) = 0;

  /// @brief Motion step: an accumulator bound to `level` with the chosen labels and, when `use_occlusion`,
  /// the label level's occlusion mask resampled to that level. Valid until the next call on the backend.
  virtual MotionAccumulator& motionAccumulator(int level, MotionLabels which, bool use_occlusion,
                                               const Config& config) = 0;

  /// @brief Occlusion mask (section 6) at the label level for the current labels and twists.
  virtual void updateOcclusion(const std::vector<Vector6d>& twists, const Config& config) = 0;

  /// @brief Label step at the label level: data costs for `twists` (occluded pixels excluded when
  /// `use_occlusion`), geometric weights, then up to `iterations` primal-dual iterations warm-started from
  /// the current labels and dual variables.
  virtual LabelStepStats labelStep(const std::vector<Vector6d>& twists, bool use_occlusion, int iterations,
                                   double tolerance, const Config& config) = 0;

  /// @brief The current labels (at the label level) in host memory.
  virtual SoftLabels downloadLabels() = 0;

  /// @brief Outputs at the input resolution, from the current labels carried to level 0: fills `result`'s
  /// soft_labels (pixels without depth on the outlier label), labels (argmax id 1..m, 0 = outlier or no
  /// depth), scene_flow, optical_flow, moved_depth, occlusion (all 0 unless detect_occlusions) and one Segment
  /// per motion label with its support and centroid (id, twist and transform are the caller's). The soft labels and
  /// scene flow only as `selection` asks (else 0x0).
  virtual void outputs(const std::vector<Vector6d>& twists, const Config& config, const OutputSelection& selection,
                       Result& result) = 0;
};

/// @brief What this process's CUDA backends have done so far (all solvers together; zeros in a build without
/// CUDA): for benchmarks, and for the test that a solve of a size seen before allocates nothing.
struct CudaCounters {
  std::uint64_t kernel_launches = 0;     ///< kernels launched; a CUB algorithm call counts as one
  std::uint64_t device_allocations = 0;  ///< cudaMalloc calls of the grow-only device buffers
  std::uint64_t pinned_allocations = 0;  ///< cudaMallocHost calls of the page-locked staging buffers
  std::uint64_t host_waits = 0;          ///< stream synchronisations: the host waiting for results it needs
  /// Bytes the carries of stream pairs uploaded: the previous result's ids, flow and moved depth where they were no
  /// longer on the device (Result::device_outputs), else a table of its ids; its dormant regions when it has any.
  std::uint64_t carry_bytes_uploaded = 0;
  /// CUDA graphs captured and instantiated (the label step's unchecked iterations, one per launch configuration not
  /// in the engine's cache of recent ones).
  std::uint64_t graph_instantiations = 0;
};
CudaCounters cudaCounters();

/// @brief Device memory in use on the current CUDA device (by all processes) and its size [bytes]; false
/// where no usable GPU (or no CUDA in the build).
bool cudaDeviceMemory(std::size_t* used, std::size_t* total);

/// @brief The output images of a solve, contiguous in host memory (the CUDA backend's one download).
struct StagedOutputs {
  int width = 0, height = 0, label_count = 0;
  const float* soft_labels = nullptr;   ///< label_count planes; null: not selected (Result::soft_labels 0x0)
  const float* scene_flow = nullptr;    ///< 3 channels; null: not selected (Result::scene_flow 0x0)
  const float* optical_flow = nullptr;  ///< 2 channels
  const float* moved_depth = nullptr;
  const std::int32_t* labels = nullptr;
  const std::uint8_t* occlusion = nullptr;
  /// Called before image `i` is read (0 soft labels, 1 scene flow, 2 optical flow, 3 moved depth, 4 labels,
  /// 5 occlusion), so that copying an image that has arrived overlaps the transfer of the next ones; null when every
  /// image is in host memory already. Called once per image, image 0 on the calling thread and the others on OpenMP
  /// threads: it must not throw, and returns 0 or an error code (the CUDA backend's cudaError_t).
  std::function<int(int)> wait_for_image;
};
/// @brief Fills result's soft_labels, scene_flow, optical_flow, moved_depth, labels and occlusion from `staged`:
/// each image copied once, into a recycled image's memory where its size matches (the soft labels then in chunks of
/// 1 MiB), else allocated and copied in one pass, on several OpenMP threads (at 1280x720, ~50 MB allocated,
/// zero-filled and copied on one thread took most of the CUDA outputs stage; then the 26 MB of soft labels on one
/// thread did). Returns the first non-zero code that wait_for_image returned (the six images are then 0x0), or 0. The
/// images `staged` leaves null become 0x0 (wait_for_image is still called for them).
int fillOutputImages(const StagedOutputs& staged, Result& result);
/// @brief Copies both frames' intensity and depth planes (`width` x `height` floats each) into `staged` in the order
/// frame1 intensity, frame1 depth, frame2 intensity, frame2 depth; several OpenMP threads from a few MB on (the CUDA
/// backend's page-locked upload buffer: the 1280x720 pyramid stage took 3.0-3.5 ms with it against 4.3 ms before, H100
/// machine, docs/PERFORMANCE.md).
void stageInputFrames(const RgbdFrame& frame1, const RgbdFrame& frame2, float* staged);

/// @brief Copies what a carry reads of `previous` into `staged` (the CUDA backend's page-locked upload buffer), one
/// after the other: its labels (int32), optical flow (2 floats per pixel), moved depth (float) and, with `dormant`, its
/// dormant regions (int32); in 256 KiB slices over the OpenMP threads from 2 MiB on. Returns the bytes (with `staged`
/// null: only counts them). The sizes are checkCarryInputs' to check.
std::size_t stageCarryInputs(const Result& previous, bool dormant, unsigned char* staged);

/// @brief Checks initial hard labels (size, values in [-1, motion_labels), motion_labels >= 1); throws
/// InputError naming the value.
void validateHardLabels(const ImageI32& hard, int motion_labels, int width, int height);
/// @brief Throws InputError unless motion_labels >= 1 (initial labels need a motion label).
void requireMotionLabels(int motion_labels);
/// @brief Checks a warm start's carried hard labels before its uncovered pixels are clustered
/// (initialiseLabelsWithUncoveredClusters): size, values in [-1, first_new), first_new >= 0; throws InputError.
void validateCarriedHardLabels(const ImageI32& hard, int first_new, int width, int height);

/// @brief True when the CUDA backend is compiled in and CUDA device `device` exists and is usable; otherwise `why`
/// says why not. The calling thread's current device is left as it was.
bool cudaBackendAvailable(std::string* why, int device = 0);
/// @brief Resolves Config::backend to Cpu or Cuda: Auto = CUDA when available else CPU; Cuda throws BackendError
/// if unavailable. `note` says what was chosen and why.
Backend resolveBackend(Backend requested, std::string* note = nullptr, int cuda_device = 0);

/// @brief The CPU backend (OpenMP): the stage functions of src/core on host images.
std::unique_ptr<SolveBackend> makeCpuSolveBackend();
/// @brief The CUDA backend on CUDA device `cuda_device`, with its own stream; throws BackendError when that device
/// is missing or unusable or the build has no CUDA.
std::unique_ptr<SolveBackend> makeCudaSolveBackend(int cuda_device = 0);
/// @brief Resolves Config::backend: Auto = CUDA when available, else the CPU (`note` says why); Cuda
/// throws BackendError when unavailable.
std::unique_ptr<SolveBackend> makeSolveBackend(Backend requested, std::string* note = nullptr, int cuda_device = 0);

}  // namespace mc_flow
