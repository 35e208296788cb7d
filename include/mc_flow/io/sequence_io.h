/**
 * @file sequence_io.h
 * @brief RGB-D sequences on disk for `mcflow run-seq` and `mcflow synth --frames`: the TUM RGB-D layout
 * (rgb.txt, depth.txt with "stamp file" lines, optional associations), folders of numbered frames, and the
 * sequence outputs (trajectories.csv, the segment ids over time as a picture).
 */
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "mc_flow/core/solver.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/io/flow_io.h"

namespace mc_flow {
namespace io {

/// @brief One frame of a sequence on disk.
struct SequenceFrameFiles {
  double stamp = 0;        ///< [s]
  std::string rgb, depth;  ///< paths
};

/// @brief The frames of a TUM RGB-D sequence directory: `associations.txt` or `associate.txt` ("t_rgb rgb t_depth
/// depth" lines) when present, else rgb.txt and depth.txt matched by nearest stamp (within `max_difference`
/// [s]; RGB frames without depth that close are skipped). '#' lines are comments. Throws InputError naming
/// the file and line for a malformed line, a missing list or an empty sequence.
std::vector<SequenceFrameFiles> listTumSequence(const std::string& dir, double max_difference = 0.02);

/// @brief The frames of a folder with `rgb/` and `depth/` subfolders of images, paired in name order (the
/// counts must match), stamped index / fps. Throws InputError naming the folder otherwise.
std::vector<SequenceFrameFiles> listNumberedFrames(const std::string& dir, double fps);

/// @brief Header of trajectories.csv.
std::string trajectoryCsvHeader();
/// @brief One row per segment of a solved pair: pair, stamp, id, vx, vy, vz [m], wx, wy, wz [rad] (over the
/// pair interval, relative to the camera), support [px], then relative to the static world: world (1: a world
/// segment), moving (1: faster than moving_min_speed / moving_min_rate), world_vx, world_vy, world_vz [m/s, the
/// centroid's velocity], world_wx, world_wy, world_wz [rad/s] (camera frame of the pair's first frame). Without
/// `world` (one per segment) those columns are empty.
std::string trajectoryCsvRows(long pair, double stamp, const Result& result,
                              const std::vector<WorldVelocity>* world = nullptr);

/// @brief The header line of odometry.csv (odometryCsvRow's columns).
std::string odometryCsvHeader();

/// @brief One line of run-seq's odometry.csv: "pair,stamp_first,stamp_second,vx,vy,vz,wx,wy,wz" and the 21 values of
/// the upper triangle of the twist's covariance (row by row, "c11,c12,...,c66"): the camera's motion over the pair,
/// C2 = C1 exp(twist) (the inverse of the static world's motion; v [m], w [rad], camera frame of the first frame), and
/// its covariance [m^2, m rad, rad^2].
std::string odometryCsvRow(long pair, const OdometryStep& step);

/// @brief The steps of an odometry.csv (its header line skipped). Throws InputError naming the file and line of a
/// malformed line.
std::vector<OdometryStep> readOdometryCsv(const std::string& path);

// tumTrajectoryLine (one line of a TUM RGB-D trajectory file): mc_flow/io/flow_io.h.

/// @brief A trajectory in the TUM RGB-D format: stamp -> pose. Lines starting with '#' and empty lines are skipped.
/// Throws InputError naming the file and line of a malformed line or a quaternion far from unit length.
std::vector<std::pair<double, Eigen::Matrix4d>> readTumTrajectory(const std::string& path);

/// @brief The segment ids over time: one column per pair, one row per id (ascending), a cell in the id's
/// colour where the id exists in that pair, darker for smaller support. `ids_per_pair[p]` = (id, support).
cv::Mat idsOverTimeImage(const std::vector<std::vector<std::pair<int, double>>>& ids_per_pair);

}  // namespace io
}  // namespace mc_flow
