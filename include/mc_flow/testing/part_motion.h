/**
 * @file part_motion.h
 * @brief How well a solve's segments move each rigid part of a synthetic scene: the segment that covers most of
 * the part, and that segment's rotation and flow errors against the part's true motion (issue 7's articulated-arm
 * target: the arm's two links in two segments, each within 1 degree).
 */
#pragma once

#include <string>
#include <vector>

#include "mc_flow/core/solver.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace mc_flow {

struct PartMotionError {
  int part_id = 0;
  std::string name;
  int pixels = 0;                 ///< pixels of the part with a motion segment in the result (labels > 0)
  int segment = 0;                ///< id of the segment covering most of them (Segment::id); 0 when none does
  double covered_fraction = 0;    ///< share of those pixels in that segment
  double true_rotation_deg = 0;   ///< the part's rotation over the pair
  double rotation_error_deg = 0;  ///< angle of exp(segment twist)^-1 exp(part twist); NaN without a segment
  /// That error's rotation vector split about the part's longest 3D axis (the principal axis of its frame-1 points)
  /// and across it: a bar's own pixels hardly constrain a rotation about its length (a 5 cm radius moves by 0.9 mm
  /// per degree), so the two tell an unobservable error from a wrong motion. NaN without a segment or with fewer than
  /// 3 points.
  double rotation_error_along_deg = 0, rotation_error_across_deg = 0;
  double flow_epe_px = 0;  ///< mean optical-flow EPE over the part's pixels not occluded in the truth
  /// Rotation error of the best rigid motion for the part's own true scene flow (least squares over its pixels,
  /// Umeyama): what one rigid motion per part can reach at all. Near 0 but for the arm's links, which bend around
  /// the elbow in the generator (synthetic_scene.cpp). NaN with fewer than 3 points.
  double rigid_fit_error_deg = 0;
};

/// @brief One entry per part of `pair` (the background first), in the order of pair.parts. Throws InputError when
/// the result's size differs from the pair's.
std::vector<PartMotionError> partMotionErrors(const Result& result, const SyntheticPair& pair);

/// @brief The true segmentation of frame 1 as a previous result, for a warm-started solve of the pair that starts
/// from the true parts (Solver::solve(frame1, frame2, K, previous)): segment k+1 = part k with a zero twist, pixels
/// with valid depth labelled by their part, the rest 0; zero flow and frame 1's own depth as the moved depth, so that
/// carrying it into frame 1 leaves the labels where they are. The solve still has to find every motion. Its energy and
/// valid_pixels stay 0, which keeps the warm solve from being re-solved cold on the energy test
/// (Config::warm_max_energy_ratio needs a previous energy per pixel).
Result truthSegmentation(const SyntheticPair& pair);

/// @brief Whether the scene's articulated arm ("upper_arm", "forearm") comes out as two segments: both links have a
/// covering segment and the two differ. False when the scene has no arm.
bool armLinksApart(const std::vector<PartMotionError>& parts);

}  // namespace mc_flow
