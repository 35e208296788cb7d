/**
 * @file static_world.h
 * @brief The static world of a pair: which segments it is, and its motion, fitted once on the union of their pixels;
 * from it the camera's own motion (odometry) and each segment's motion relative to the world. Design:
 * docs/ALGORITHM.md, "Static world and odometry".
 */
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/se3.h"

namespace mc_flow {

class LabelStore;
struct Segment;

/// @brief Which segments of a pair are the static world, and how its points moved.
struct StaticWorld {
  bool found = false;       ///< false: no segment (a pair with no motion label)
  std::vector<int> ids;     ///< the world's segment ids (Segment::id)
  std::vector<int> labels;  ///< their label indices (Result::segments order)
  /// Motion of the world's points over the interval in the camera frame of frame 1 (P2 = exp(twist) P1): one robust
  /// rigid fit on the union of the world segments' pixels. The camera moved by its inverse.
  Vector6d twist = Vector6d::Zero();
  Matrix6d covariance = Matrix6d::Zero();  ///< of `twist` [m^2, m rad, rad^2]
  double pixels = 0;                       ///< weighted pixels of the fit (processing level)
  /// Why these segments: "prior" (agree with the camera-motion prior), "previous" (the previous pair's world ids),
  /// "widest" (the segment of most pixels), "outgrown" (the widest, which has outgrown the previous world by
  /// Config::world_outgrown_ratio) or "behind" (the segment that the remembered world, or the widest, is in front of:
  /// DepthOrder).
  std::string chosen_by;

  /// @brief Whether the segment of this id (Segment::id) is part of the world.
  bool contains(int segment_id) const;
};

/// @brief Which segment is in front of which where they meet, over the depth edges of a pair's frame 1: neighbouring
/// pixels (4-neighbours) of two different segments whose depths differ by more than Config::world_depth_edge.
/// Moving things are in front of the room they move in: the static world is what they hide.
struct DepthOrder {
  int segments = 0;
  std::vector<double> front;  ///< segments x segments, row-major: edges where segment a (row) is nearer than b

  /// @brief Of the depth edges between the segment groups `a` and `b` (indices in `segments` order), the share where a
  /// is nearer; `edges` receives their count. 0 with no edge.
  double frontShare(const std::vector<int>& a, const std::vector<int>& b, double& edges) const;
};

/// @brief The depth order of `segments` over `segment_ids` (Result::labels: a Segment::id per pixel, 0 for none) and
/// `points` (frame 1's points, 3 channels, NaN z where depth is invalid) of a level `step` times coarser (point (x, y)
/// takes the id at the centre of its step x step block). Pixels whose id is not a segment's, or without depth, take no
/// part. A seam is a depth edge where the jump exceeds `depth_edge` and three times the depth step beside it on either
/// side (a slanted surface is no edge). Throws InputError when `points` is not 3 channels or does not fit inside the
/// ids at that step.
DepthOrder depthOrderOf(const ImageI32& segment_ids, const std::vector<Segment>& segments, const ImageF& points,
                        int step, double depth_edge);

/// @brief The covariance of a twist fitted by the motion step's Gauss-Newton model: (E / (2 N - 6)) H^-1 with H the
/// curvature (the normalised Cauchy cost E(xi + d) ~ E + 2 g^T d + d^T H d), E the cost and N the pixels (two residuals
/// each): the inverse normal equations scaled by the residual variance, times Config::world_covariance_scale (the
/// residuals of neighbouring pixels are not independent). A ridge keeps planar scenes' unconstrained directions finite.
/// Too few pixels (under 6) or no curvature: the identity (1 m, 1 rad).
Matrix6d twistCovariance(const Matrix6d& curvature, double cost, double pixels, const Config& config);

/// @brief Chooses the static world among `segments` (labels 0..n-1 of `labels`, whose twists they hold) and fits its
/// motion on the union of the chosen segments' pixels (refitUnions, world_fit_iterations steps from the widest world
/// segment's twist). In this order: the segments whose pixels `camera_motion_prior` (the camera's motion over the
/// pair, frame 1 -> frame 2, e.g. from wheel odometry; null: none) explains as well as their own motions up to
/// merge_refit_tolerance (oneMotionExplains, against the widest segment's noise level); else the segments carrying an
/// id of `previous_world_ids` (a stream keeps its world), unless the widest segment is not among them and either they
/// are in front of it (`depth_order`, Config::world_front_share: "behind") or it holds more than
/// Config::world_outgrown_ratio times their pixels and is not in front of them ("outgrown"); else the widest segment,
/// or the second widest when the widest is in front of it ("behind"). `depth_order` null: depth order decides nothing.
/// Then, unless a prior chose (Config::world_joins_pieces), every other segment that the chosen world's motion (its
/// widest segment's) explains and that is not in front of the world joins it; a remembered world is its widest
/// segment and its other segments are tested again in the same way, each allowed Config::world_piece_keep_ratio times
/// a join's cost increase (without the depth order the memory is kept as it is). The world's motion is fitted on the
/// union from its widest chosen segment's twist; its covariance is twistCovariance's plus the floor
/// Config::world_covariance_floor_translation² and world_covariance_floor_rotation² on the diagonal (what real sensors
/// leave that the fit cannot see). Also fills each segment's twist covariance (`segment_covariances`, in `segments`
/// order; twistCovariance's alone). Passes over the label level's pixels: one, one more with a prior, one more where a
/// segment is a candidate to join, and one per fit iteration.
StaticWorld estimateStaticWorld(LabelStore& labels, const std::vector<Segment>& segments,
                                const std::vector<int>& previous_world_ids, const Eigen::Matrix4d* camera_motion_prior,
                                bool use_occlusion, const Config& config, std::vector<Matrix6d>& segment_covariances,
                                const DepthOrder* depth_order = nullptr);

/// @brief A segment's motion relative to the static world over the interval, in the camera frame of frame 1:
/// exp(-world.twist) exp(segment twist), as a velocity [m/s at the segment's centroid, rad/s] with its covariance
/// (the two fits' covariances added, first order).
struct WorldVelocity {
  Eigen::Vector3d linear = Eigen::Vector3d::Zero();   ///< [m/s] of the centroid
  Eigen::Vector3d angular = Eigen::Vector3d::Zero();  ///< [rad/s]
  Matrix6d covariance = Matrix6d::Zero();             ///< of (linear, angular) [(m/s)^2, ...]
  bool moving = false;  ///< faster than moving_min_speed or moving_min_rate (never for a world segment)
};
WorldVelocity worldVelocity(const Segment& segment, const Matrix6d& segment_covariance, const StaticWorld& world,
                            bool is_world, double interval_s, const Config& config);

}  // namespace mc_flow
