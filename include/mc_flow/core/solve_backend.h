/**
 * @file solve_backend.h
 * @brief The stages of Algorithm 1 behind one interface, so that the orchestration (src/core/solver.cpp)
 * exists once and each backend keeps the state of a solve where it computes: the CPU backend in host
 * images (src/core/solve_backend.cpp), the CUDA backend in device buffers (cuda/solve_backend.cu) that
 * stay there from the upload of the pyramids to the download of the final labels.
 *
 * The host only takes the decisions (which labels merge or split, the Levenberg-Marquardt steps,
 * convergence) from small numbers the backend returns: per-label supports and moments, the normal
 * equations of the motion step, energies. Design and status: docs/GPU.md, "Stage-level backend".
 */
#pragma once

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

namespace mc_flow {

/// @brief Which labels the motion step's accumulator sees at a level.
enum class MotionLabels {
  Current,        ///< the solve's soft labels, resampled from the label level to that level
  AllValidAsOne,  ///< one motion label over every valid pixel (the dominant-motion initialisation)
};

/// @brief Result of one label step (data costs, then primal-dual iterations from the warm start).
struct LabelStepStats {
  int iterations = 0;
  double energy = 0;        ///< E(u) of eq. 4 at the end
  double mean_change = 0;   ///< sum over planes of |u_after - u_before|, divided by the pixel count
};

/// @brief The solve's state and stages. One per Solver; not thread-safe.
class SolveBackend : public LabelStore {
 public:
  ~SolveBackend() override = default;
  virtual Backend kind() const = 0;

  /// @brief Takes both frames' pyramids for the solve (the CUDA backend uploads every level once).
  /// They must outlive the solve. Resets the labels, the occlusion mask and the dual variables.
  virtual void loadPyramids(const Pyramid& frame1, const Pyramid& frame2, const Config& config) = 0;

  /// @brief Hard initial labels at `level` (K-means' assignment or labels carried from the previous pair):
  /// `hard` holds a motion label in [0, motion_labels) per pixel, or -1 for the outlier label; pixels
  /// without depth go to the outlier label whatever `hard` says. Label count = motion_labels + 1.
  virtual void initialiseLabels(int level, const ImageI32& hard, int motion_labels) = 0;
  /// @brief Pyramid level the labels live at.
  virtual int labelLevel() const = 0;
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
};

/// @brief Checks initial hard labels (size, values in [-1, motion_labels), motion_labels >= 1); throws
/// InputError naming the value.
void validateHardLabels(const ImageI32& hard, int motion_labels, int width, int height);

/// @brief The CPU backend (OpenMP): the stage functions of src/core on host images.
std::unique_ptr<SolveBackend> makeCpuSolveBackend();
/// @brief The CUDA backend; throws BackendError when no usable GPU is present or the build has no CUDA.
std::unique_ptr<SolveBackend> makeCudaSolveBackend();
/// @brief Resolves Config::backend: Auto = CUDA when available, else the CPU (`note` says why); Cuda
/// throws BackendError when unavailable.
std::unique_ptr<SolveBackend> makeSolveBackend(Backend requested, std::string* note = nullptr);

}  // namespace mc_flow
