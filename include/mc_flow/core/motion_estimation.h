/**
 * @file motion_estimation.h
 * @brief Motion step: the twists of all labels solved jointly by Cauchy IRLS under the
 * motion-interpolation model (eq. 2), coarse to fine.
 */
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

/// @brief Why the IRLS loop of one level stopped (as dvo_slam reports per level).
enum class MotionStop {
  NoLabels,        ///< nothing to estimate (no motion label)
  IterationLimit,  ///< motion_iterations_per_level (or _refine) reached
  SmallUpdate,     ///< the largest twist update fell below motion_min_update
  TooFewPixels,    ///< fewer than 6 pixels carried residuals
  SolveFailed,     ///< the damped normal equations gave a non-finite step
};
std::string toString(MotionStop stop);

struct MotionLevelStats {
  int level = 0;  ///< pyramid level (set by the caller; 0 = input resolution)
  int iterations = 0;
  int pixels_used = 0;
  double cost_before = 0;  ///< robust cost (normalised Cauchy) at the first iteration
  double cost_after = 0;   ///< at the last iteration
  MotionStop stop = MotionStop::NoLabels;
  double accumulate_ms = 0;  ///< wall time in the accumulator (per-pixel sums; on a GPU, launches and the wait)
  double solve_ms = 0;       ///< wall time in the step control and the damped solves (host)
  int largest_block = 0;     ///< most labels coupled in one solve (labels that share no pixel are solved apart)
};

/// @brief The normal equations of one IRLS linearisation over all motion labels (6 unknowns per label).
struct MotionNormalEquations {
  Eigen::MatrixXd H;             ///< 6n x 6n, sum over pixels of m w_i w_j sum_kinds w(r) J^T J
  Eigen::VectorXd g;             ///< 6n, sum over pixels of m w_i sum_kinds w(r) J^T r
  Eigen::VectorXd label_cost;    ///< robust cost shared out to the labels by their interpolation weights
  Eigen::VectorXd label_pixels;  ///< weighted pixel count per label
  double cost = 0;               ///< total robust cost (out-of-view pixels included)
  int pixels = 0;                ///< pixels that contributed residuals
  void reset(int labels);
  void add(const MotionNormalEquations& other);
};

/// @brief Builds the normal equations at given twists (the expensive, per-pixel part of the motion step).
/// The CPU and CUDA implementations compute the same sums; the solve and the per-label step control stay in
/// estimateMotionsAtLevel.
class MotionAccumulator {
 public:
  virtual ~MotionAccumulator() = default;
  /// @brief Fixes the level's images, labels and occlusion mask for the following accumulate() calls
  /// (they must outlive them).
  virtual void setLevel(const PyramidLevel& frame1, const PyramidLevel& frame2, const SoftLabels& labels,
                        const ImageU8* occluded, const Config& config) = 0;
  /// @brief Linearises at `twists` (one per motion label) and writes the sums into `out`.
  virtual void accumulate(const std::vector<Vector6d>& twists, MotionNormalEquations& out) = 0;
  /// @brief What a label's cost model needs (label_adaptation.h): each label's diagonal block of H, its part of g,
  /// its cost and pixels, and the totals, the same values accumulate() gives them; the blocks between labels may be
  /// left zero. The CUDA accumulator then skips the label pairs' sums (half of a pass at 320x240); the default (the
  /// CPU's, where the pairs cost little) is accumulate().
  virtual void accumulateLabelBlocks(const std::vector<Vector6d>& twists, MotionNormalEquations& out) {
    accumulate(twists, out);
  }
  /// @brief Runs the whole IRLS loop of the bound level where the sums are computed, with the step control of
  /// motion_step_control.h, updating `twists` and filling `stats` as estimateMotionsWith's host loop does. Returns
  /// false when this accumulator only builds sums (the host loop then runs; the CPU's case).
  virtual bool iterateLevel(std::vector<Vector6d>& twists, const Config& config, MotionLevelStats& stats) {
    (void)twists;
    (void)config;
    (void)stats;
    return false;
  }
  virtual std::string name() const = 0;
};

/// @brief The CPU implementation (OpenMP, static schedule: deterministic for a given thread count).
std::unique_ptr<MotionAccumulator> makeCpuMotionAccumulator();
/// @brief The CUDA implementation on host-memory levels (setLevel uploads; tests compare it with the CPU's, the CUDA
/// SolveBackend binds its device-resident levels instead); throws BackendError when no usable CUDA device is present
/// or the build has no CUDA.
std::unique_ptr<MotionAccumulator> makeCudaMotionAccumulator();
/// @brief Cost charged to a pixel whose warp leaves the view (as if both residuals were 10 Cauchy scales).
double motionOutOfViewCost(const Config& config);

/// @brief IRLS at one level. `labels` has the level's size; `occluded` (may be null) excludes pixels.
/// `twists` holds one twist per motion label (labels.count - 1; otherwise InputError) and is updated in place.
/// `accumulator` builds the normal equations (null: a CPU one).
MotionLevelStats estimateMotionsAtLevel(const PyramidLevel& frame1, const PyramidLevel& frame2,
                                        const SoftLabels& labels, const ImageU8* occluded,
                                        std::vector<Vector6d>& twists, const Config& config,
                                        MotionAccumulator* accumulator = nullptr);

/// @brief Solves H delta = -g where H is 6n x 6n with 6x6 blocks per label pair (diagonal blocks damped), one LDLT
/// per group of labels: the groups are joined by the couplings at least `min_coupling` strong (`motionLabelsCoupled`,
/// Config::motion_min_coupling), so labels that share no pixel or only weakly coupled ones are solved apart, the
/// blocks between groups taken as zero; inside a group every block is kept (a principal submatrix stays positive
/// semidefinite, a matrix with some inner blocks zeroed need not). With `min_coupling` 0: the solution of the whole
/// matrix up to rounding. Returns the size of the largest group in labels.
int solveCoupledBlocks(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, Eigen::VectorXd& delta, double min_coupling);

/// @brief The same IRLS with an accumulator already bound to a level (setLevel called, or a backend's
/// device-resident one); `twists` holds one twist per motion label of that binding.
MotionLevelStats estimateMotionsWith(MotionAccumulator& bound_accumulator, std::vector<Vector6d>& twists,
                                     const Config& config);

}  // namespace mc_flow
