/**
 * @file solver.h
 * @brief The MC-Flow solver (Algorithm 1): K-means initialisation, then alternating motion step,
 * label step and label-count update; occlusion mask; scene flow outputs.
 */
#pragma once

#include <memory>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"
#include "mc_flow/core/static_world.h"

namespace mc_flow {

class SolveBackend;

/// @brief One rigid part. The twist and transform map frame-1 points to where they are in frame 2
/// (camera optical frame of frame 1), over the frame interval (not per second).
struct Segment {
  int id = 0;  ///< >= 1, the value of its pixels in Result::labels (0: outlier or no depth); 1..m for
               ///< a pair solved alone, kept through a stream when the previous result is passed on
  Vector6d twist = Vector6d::Zero();                        ///< (v [m], w [rad]) over the interval
  Eigen::Matrix4d transform = Eigen::Matrix4d::Identity();  ///< exp(twist)
  double support = 0;                                       ///< sum of u over the pixels (input resolution)
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();       ///< [m] support-weighted centroid of its points
  Matrix6d covariance = Matrix6d::Zero();  ///< of `twist` (twistCovariance of its pixels' fit at the processing level)
};

/// @brief Wall-clock time per stage [ms]. merge_test is the part of adaptation spent in the one-motion merge test
/// (mergeWhereOneMotionExplains).
struct StageTimings {
  double preprocessing = 0, initialisation = 0, motion = 0, labels = 0, adaptation = 0, occlusion = 0, outputs = 0,
         total = 0, merge_test = 0;
};

struct OuterIterationStats {
  int iteration = 0;
  int labels_before = 0;  ///< motion labels at the start (outlier label not counted)
  int labels_after = 0;   ///< after merging / removal
  int merged = 0, removed = 0, split = 0;
  int merge_rounds = 0, merge_pairs_tested = 0;  ///< the one-motion merge test's rounds and refitted pairs
  double smallest_refused_merge = 0;             ///< predicted data-cost increase of the cheapest merge not taken
  int motion_iterations = 0;                     ///< IRLS iterations summed over levels
  std::vector<MotionLevelStats> motion_levels;   ///< the motion step per level, coarse to fine
  int label_iterations = 0;                      ///< primal-dual iterations
  double label_change = 0;                       ///< mean |u_k+1 - u_k| at the label level
  double energy = 0;                             ///< E(u) of eq. 4 after the label step
};

/// @brief How a solve started.
enum class StartKind {
  Cold,         ///< K-means on 3D points (no previous result, or Config::warm_start off)
  Warm,         ///< from the previous pair's labels and motions
  ColdFallback  ///< a previous result was given but not used: Result::start_note says why
};
std::string toString(StartKind start);

/// @brief Which of a Result's optional full-resolution images a solve fills; one left out stays 0x0 and, on the GPU, is
/// neither downloaded nor copied (at 640x480 the soft labels of 7 planes are 8.6 MB, the scene flow 3.7 MB). The
/// labels, optical flow, moved depth and occlusion mask are always filled: a stream's next pair carries its segments
/// with them.
struct OutputSelection {
  bool soft_labels = true;  ///< Result::soft_labels
  bool scene_flow = true;   ///< Result::scene_flow
};

/// @brief Everything the solver produces. Images are at the input resolution.
struct Result {
  int width = 0, height = 0;
  Intrinsics intrinsics;
  std::vector<Segment> segments;
  SoftLabels soft_labels;  ///< planes 0..m-1 = segments (in order), plane m = outlier; 0x0 when not selected
  ImageI32 labels;         ///< argmax segment id 1..m; 0 = outlier or no depth
  ImageU8 occlusion;       ///< 255 = occluded
  ImageF scene_flow;       ///< 3 channels [m], frame-1 camera frame; NaN where depth is invalid; 0x0 when not selected
  ImageF optical_flow;     ///< 2 channels [px]; NaN where depth is invalid
  ImageF moved_depth;      ///< [m] depth of each frame-1 point after its motion (seen from frame 2); NaN where invalid
  /// Which solve of the CUDA backend left labels, optical_flow and moved_depth on the device (a serial; 0: none, the
  /// CPU's): the next pair's carry reads them there while they are still the backend's latest outputs and this result
  /// holds them in the memory the solve filled (a moved result does, a copy does not), and uploads these images
  /// otherwise. A caller that changes those images in place (or the segments' order) sets it to 0.
  std::uint64_t device_outputs = 0;
  StageTimings timings;
  std::vector<OuterIterationStats> iterations;
  double energy = 0;     ///< final E(u) (processing level)
  int valid_pixels = 0;  ///< frame-1 pixels with valid depth at the processing level
  // ---- stream mode (Solver::solve with the previous pair's result) ----
  StartKind start = StartKind::Cold;
  std::string start_note;  ///< why a given previous result was not used (empty otherwise)
  int next_id = 1;         ///< the id the next new segment gets (ids are never reused within a stream)
  std::vector<std::pair<int, int>> merged_ids;  ///< (id, id it merged into) for the previous pair's segments
  std::vector<int> ended_ids;    ///< ids of the previous pair's segments that neither continue nor merged
  std::vector<int> revived_ids;  ///< ids that had merged or ended in an earlier pair and are back
  /// Ids merged or ended within the last Config::id_memory_pairs pairs: (id, pairs since) and their regions on
  /// frame 1 (0 = none), carried forward with the scene, so that such a segment can take its id back.
  std::vector<std::pair<int, int>> dormant_ids;
  ImageI32 dormant_regions;
  /// The static world: its segments (persistent over a stream through their ids) and its motion, fitted once on their
  /// union (static_world.h); the camera moved by the inverse of world.twist.
  StaticWorld world;
  int processing_width = 0, processing_height = 0;
  int pyramid_levels = 0;
  Backend backend_kind = Backend::Cpu;  ///< the backend that ran (Cpu or Cuda, never Auto)
  std::string backend;                  ///< toString(backend_kind): "cpu" or "cuda"
  std::string backend_note;             ///< why Auto chose what it chose
};

/// @brief The motion labels over a solve's outer iterations: the initial count, then the count after each update
/// ("20 > 3 > 2"); with `changes`, each update's merges and splits too ("20 > 3(-17+0) > 2(-1+0)"). For benchmarks
/// and logs: a reader sees the label-count decisions.
std::string labelCountTrace(const Result& result, bool changes = false);

/// @brief Solver with a fixed Config. Not thread-safe; reuse one per stream.
class Solver {
 public:
  /// @brief Validates the config (throws ConfigError) and resolves the backend (throws BackendError
  /// when CUDA is forced but unusable).
  explicit Solver(const Config& config);
  /// @brief With a backend made by the caller instead of from Config::backend (SequencePipeline's
  /// SolveBackendFactory, e.g. one with an injected fault); `backend_note` becomes Result::backend_note.
  /// Throws ConfigError for a bad config or a null backend.
  Solver(const Config& config, std::unique_ptr<SolveBackend> backend, std::string backend_note);
  ~Solver();
  Solver(const Solver&) = delete;
  Solver& operator=(const Solver&) = delete;

  /// @brief Solves one pair. Throws InputError for bad input (sizes, non-finite values, no valid depth,
  /// bad intrinsics).
  Result solve(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K);

  /// @brief Solves the next pair of a stream: `previous` is the result of the pair whose frame 2 is this
  /// `frame1` (same size). With Config::warm_start its segments are carried into frame 1 and start the solve
  /// with their motions (constant velocity); pixels they do not cover go through K-means. The carried
  /// solution is refused, and the pair solved cold, when the carried labels cover less than
  /// warm_min_coverage of the valid pixels, or when the warm result's energy per pixel exceeds
  /// warm_max_energy_ratio times the previous pair's and a cold solve does better. Segment ids persist
  /// either way (a cold solve matches them by overlap with the carried segments).
  Result solve(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, const Result& previous);

  /// @brief As solve(frame1, frame2, K[, *previous]) (`previous` may be null), with the camera's motion over the pair
  /// from another source (frame 1 -> frame 2 in the camera frame of frame 1, e.g. wheel odometry through TF): the
  /// static world is then the segments whose pixels that motion explains (Result::world, chosen_by "prior"), when any.
  Result solve(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, const Result* previous,
               const Eigen::Matrix4d& camera_motion_prior);

  /// @brief Hands back a result the caller no longer needs: the next solve fills its output images into that
  /// result's memory instead of fresh allocations (at 1280x720 about 50 MB, whose first touch cost 5-20 ms of page
  /// faults per pair). Optional; a stream hands back the result that the new one replaces. `finished` is left empty.
  /// Like solve(), not to be called while another thread uses this Solver.
  void recycle(Result&& finished);

  /// @brief The optional output images the following solves fill (OutputSelection; all by default).
  void setOutputs(const OutputSelection& selection);
  const OutputSelection& outputs() const;

  const Config& config() const;
  std::string backendName() const;
  /// @brief The resolved backend (Cpu or Cuda).
  Backend backendKind() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mc_flow
