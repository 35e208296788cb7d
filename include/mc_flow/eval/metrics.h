/**
 * @file metrics.h
 * @brief The paper's metrics (Tables 1-2) plus ground-truth comparisons for synthetic scenes, and a camera trajectory
 * scored as the TUM RGB-D benchmark does (also `mcflow eval-traj`'s maths, io/trajectory_eval.h).
 *
 * Library mc_flow_eval (installed; Eigen and the core only): the `mcflow` tool's evaluations, the benchmarks, the
 * tests.
 */
#pragma once

#include <cstddef>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "mc_flow/core/image.h"
#include "mc_flow/core/se3.h"

namespace mc_flow {

/// @brief The element at index size / 2 of the sorted values (the upper median for an even count); 0 when empty.
double median(std::vector<double> values);
/// @brief The nearest-rank percentile: the value at rank ceil(q n) of the sorted values (q in (0, 1]); 0 when empty.
double percentile(std::vector<double> values, double q);

struct FlowErrors {
  double epe = 0;      ///< mean end-point error [px]
  double aae_deg = 0;  ///< mean angular error [deg] (Barron et al., on (u, v, 1))
  std::size_t pixels = 0;
};

struct ResidualRmse {
  double photometric = 0;  ///< intensity in [0, 1]
  double geometric = 0;    ///< [m]
  std::size_t pixels = 0;
};

/// @brief EPE and AAE of optical flow over pixels where both are finite and `excluded` (may be null) is 0.
FlowErrors opticalFlowErrors(const ImageF& estimate, const ImageF& truth, const ImageU8* excluded);

/// @brief Mean 3D end-point error [m] of scene flow, same pixel selection.
double sceneFlowEpe(const ImageF& estimate, const ImageF& truth, const ImageU8* excluded,
                    std::size_t* pixels = nullptr);

/// @brief Table 1: warp frame 2 back with the scene flow (P2 = P + flow, sampled at pi(P2)) and take the
/// RMSE of I1 - I2(pi(P2)) and of [P2]_z - Z2(pi(P2)) over valid, non-excluded pixels.
/// A null scene flow means zero flow.
ResidualRmse warpResidualRmse(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K,
                              const ImageF* scene_flow, const ImageU8* excluded);

/// @brief Fraction of pixels (truth >= 0 and estimate >= 0) whose estimated segment maps to their true part
/// under the best one-to-one matching (greedy on overlap).
double segmentationAgreement(const ImageI32& estimate, const ImageI32& truth);

/// @brief Fraction of valid pixels where two binary masks (non-zero = set) agree; `valid` may be null.
double maskAgreement(const ImageU8& a, const ImageU8& b, const ImageU8* valid);

/// @brief Intersection over union of two binary masks (non-zero = set) over valid pixels (`valid` may be null); 1 when
/// both are empty (they agree).
double maskIou(const ImageU8& a, const ImageU8& b, const ImageU8* valid);

/// @brief How a set of estimated segments (pixels of `labels` carrying one of `ids`) overlaps one true part (pixels of
/// `truth` equal to `truth_id`), over valid pixels (`valid` may be null).
struct RegionOverlap {
  std::size_t estimate = 0, truth = 0, common = 0;                                      ///< pixels
  double coverage() const { return truth ? double(common) / double(truth) : 0.0; }      ///< of the truth
  double purity() const { return estimate ? double(common) / double(estimate) : 0.0; }  ///< of the estimate
  /// The estimate is that part: it covers the majority of the part's pixels, and most of its pixels are the part's.
  bool matches() const { return coverage() > 0.5 && purity() > 0.5; }
};
RegionOverlap regionOverlap(const ImageI32& labels, const std::vector<int>& ids, const ImageI32& truth, int truth_id,
                            const ImageU8* valid);

/// @brief Normalised estimation error squared e^T C^-1 e of an error `error` whose claimed covariance is `covariance`:
/// chi-square distributed with 6 degrees of freedom when the estimate is unbiased and the covariance right.
double nees(const Vector6d& error, const Matrix6d& covariance);

/// @brief The `probability` quantile of the chi-square distribution with `dof` degrees of freedom (bisection on its
/// CDF, the regularised lower incomplete gamma function; relative accuracy 1e-10). Throws InputError outside
/// dof > 0, 0 < probability < 1.
double chiSquareQuantile(double dof, double probability);

using StampedPoses = std::vector<std::pair<double, Eigen::Matrix4d>>;  ///< (stamp [s], camera-to-world pose)

/// @brief A camera trajectory's errors as the TUM RGB-D benchmark defines them (Sturm et al., IROS 2012).
struct TrajectoryErrors {
  int matched = 0;               ///< estimated poses with a ground-truth pose within max_difference
  double ate_rmse_m = 0;         ///< after the rigid alignment (no scale)
  double rpe_frame_trans_m = 0;  ///< RMSE of consecutive matched frames' relative motion: translation [m]
  double rpe_frame_rot_deg = 0;  ///< ... rotation [deg]
  int rpe_frame_pairs = 0;
  double rpe_second_trans_m = 0;  ///< over about one second (the first frame at least 1 s later) [m]
  double rpe_second_rot_deg = 0;  ///< [deg]
  int rpe_second_pairs = 0;
  Eigen::Matrix4d alignment = Eigen::Matrix4d::Identity();             ///< ground truth <- estimate
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> positions;  ///< (ground truth, aligned estimate) per match
};

/// @brief Matches each estimated pose (stamp + time_offset) to the nearest ground-truth stamp within max_difference
/// [s] and scores the matches: the absolute trajectory error (RMSE of the positions after the rigid alignment that
/// minimises it, Umeyama without scale) and the relative pose error (the error of the motion over consecutive frames
/// and over about one second). Throws InputError when fewer than 3 poses match (naming the counts).
TrajectoryErrors evaluateTrajectory(const StampedPoses& ground_truth, const StampedPoses& estimate,
                                    double max_difference, double time_offset);

/// @brief One step of an odometry: the camera's motion from its frame at `first` to its frame at `second` [s],
/// C2 = C1 exp(twist) with twist = (v [m], w [rad]) in the camera frame at `first`, and the twist's covariance.
struct OdometryStep {
  double first = 0, second = 0;
  Vector6d twist = Vector6d::Zero();
  Matrix6d covariance = Matrix6d::Identity();
};

/// @brief Whether an odometry's covariances match its errors: the NEES of each step against the ground truth's motion
/// between the same instants, which chi-square with 6 degrees of freedom describes when the covariances are right.
struct OdometryConsistency {
  int matched = 0;                     ///< steps whose both stamps have a ground-truth pose within max_difference
  double nees_median = 0;              ///< median(): chi2_6's median is 5.35
  double nees_mean = 0;                ///< 6 when consistent
  double inside95 = 0;                 ///< the share of steps within chi2_6's central 95 % [1.24, 14.45]
  double mean_low = 0, mean_high = 0;  ///< the central 95 % of the mean of `matched` consistent NEES values
};

/// @brief Scores `steps` against `ground_truth` (camera-to-world poses): each step's stamps (+ time_offset) are matched
/// to the nearest ground-truth stamps within max_difference [s] (as evaluateTrajectory), the true step is
/// log(G1^-1 G2), and the NEES is (twist - true)^T covariance^-1 (twist - true). Throws InputError when no step
/// matches, or a covariance is not symmetric positive definite (naming the step).
OdometryConsistency odometryConsistency(const StampedPoses& ground_truth, const std::vector<OdometryStep>& steps,
                                        double max_difference, double time_offset);

}  // namespace mc_flow
