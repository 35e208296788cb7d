/**
 * @file sequence.h
 * @brief One RGB-D stream, frame by frame: preprocessing to the processing resolution, pairing and the
 * reset policy, the warm start, persistent segment ids and each segment's accumulated pose. The nodelet and
 * `mcflow run-seq` both drive this class; it knows nothing of ROS or files. Design: docs/STREAMS.md.
 */
#pragma once

#include <any>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/core/static_world.h"

namespace mc_flow {

class SolveBackend;

/// @brief Makes a pipeline's solve backends (the first one, a new one per setConfig, the CPU one after a GPU
/// failure) for the requested Backend; `note` becomes Result::backend_note. The default is makeSolveBackend. Tests
/// return backends with an injected fault this way (mc_flow/testing/fault_injection.h). When the requested backend
/// throws BackendError, the factory is asked for the CPU one (see the constructor).
using SolveBackendFactory = std::function<std::unique_ptr<SolveBackend>(Backend requested, std::string* note)>;

/// @brief The downsampling factor for an input `width`: `requested` > 0 is used as is (a power of two,
/// else ConfigError); 0 picks the power of two that brings the width closest to 320 px (the paper's
/// resolution: 640 -> 2, 320 -> 1, 1280 -> 4).
int chooseDownsample(int requested, int width);

/// @brief A frame at `factor` times fewer pixels per axis by the pyramid's rules (depth: neighbours within
/// `depth_range` [m] of the block's median; intensity: [1 3 3 1] smoothing), halving log2(factor) times;
/// odd last columns/rows are dropped, so the principal point needs no shift (Intrinsics::scaled). Taken by value:
/// a caller that moves its frame in saves a copy of it.
RgbdFrame downsampleFrame(RgbdFrame frame, int factor, double depth_range);

/// @brief One frame of a stream at the input resolution.
struct StreamFrame {
  RgbdFrame frame;     ///< intensity [0, 1], depth [m] (0 or NaN = invalid)
  Intrinsics K;        ///< of `frame`
  double stamp = 0;    ///< [s]
  std::string source;  ///< camera / frame id: a change starts a new sequence
  std::any extra;      ///< the caller's data carried with the frame (e.g. a display image)
  /// The camera's optical frame in another source's odometry frame at `stamp` (e.g. wheel odometry through TF). When
  /// both frames of a pair have one, the camera's motion between them is the static world's prior
  /// (estimateStaticWorld: the segments it explains are the world).
  std::optional<Eigen::Matrix4d> camera_pose_prior;
};

/// @brief A frame as the solver sees it: at the processing resolution.
struct PreparedFrame {
  RgbdFrame frame;
  Intrinsics K;
  double stamp = 0;
  std::string source;
  int downsample = 1;  ///< input pixels per processing pixel (per axis)
  int input_width = 0, input_height = 0;
  std::any extra;
  std::optional<Eigen::Matrix4d> camera_pose_prior;
};

/// @brief A segment's motion accumulated since it appeared (camera frame of its first pair's frame 1).
struct SegmentTrack {
  Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();  ///< product of its transforms, latest first
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();    ///< [m] its centroid moved to the latest frame
  long first_pair = 0, last_pair = 0;
};

/// @brief The camera's own motion, integrated over the stream from the static world's motion of each solved pair.
/// Convention (docs/ALGORITHM.md, "Static world and odometry"): `pose` is the camera's optical frame (REP 103: x right,
/// y down, z forward) in the odometry frame, which is the optical frame of the pipeline's first frame (identity there).
/// A stream reset or a failed pair holds the pose (no motion is known over the gap; odometry stays continuous, REP
/// 105).
struct Odometry {
  Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();
  Matrix6d pose_covariance = Matrix6d::Zero();  ///< of a perturbation exp(d) on the right of `pose` (camera frame)
  Vector6d velocity = Vector6d::Zero();         ///< the camera's (v [m/s], w [rad/s]) over the last pair, camera frame
  Matrix6d velocity_covariance = Matrix6d::Zero();
  double stamp = 0;  ///< [s] of the frame `pose` belongs to
  long pairs = 0;    ///< solved pairs integrated
};

/// @brief What one frame did.
struct SequenceStep {
  enum class Outcome {
    Solved,         ///< a pair (first, second) was solved: `result`
    Started,        ///< the frame starts a sequence (the first, or after a reset): nothing to solve yet
    RepeatedStamp,  ///< the stamp repeats the previous frame's: the frame is dropped
    PairFailed,     ///< the solver refused the pair (`problem`); the frame is kept as the next pair's first
  };
  Outcome outcome = Outcome::Started;
  std::string reset_key;                 ///< "back", "gap" or "input" when the frame started a new sequence after one
  std::string reset_reason;              ///< why, in words
  std::string problem;                   ///< PairFailed: the solver's message
  std::string backend_fallback;          ///< the GPU failed: the solver continues on the CPU (the pair is failed)
  const PreparedFrame* first = nullptr;  ///< Solved: the pair's frames (valid until the next push)
  const PreparedFrame* second = nullptr;
  const Result* result = nullptr;  ///< Solved (valid until the next push)
  long pair_index = -1;            ///< Solved: 0, 1, ... over the pipeline's life
  /// Solved: each segment's motion relative to the static world (result->segments order).
  std::vector<WorldVelocity> world_velocities;
};

/// @brief Pairs consecutive frames of one stream and solves them (see the file comment). Not thread-safe.
class SequencePipeline {
 public:
  /// `downsample`: see chooseDownsample (0 = automatic). `max_pair_interval` [s]: a longer gap starts a new
  /// sequence. Throws ConfigError for a bad config, a negative interval or a downsample that is not 0 or a
  /// power of two. A backend that cannot be made (BackendError: backend=cuda without a usable GPU, or a cuda_device
  /// that does not exist) does not stop the stream: the pipeline solves on the CPU, backendUnavailable() and every
  /// Result::backend_note say why ("cpu (fallback: ...)", naming the device count for a missing device), and the
  /// caller warns once. `make_backend`: see SolveBackendFactory (empty: makeSolveBackend).
  SequencePipeline(const Config& config, int downsample, double max_pair_interval,
                   SolveBackendFactory make_backend = {});

  /// @brief Prepares the frame and, when it continues the sequence, solves the pair (previous, frame) (warm
  /// started from the previous pair's result when Config::warm_start). Frames whose stamps go back, follow a gap
  /// longer than max_pair_interval, or come from another source or size start a new sequence. Throws
  /// InputError when the frame itself is unusable (it is then not kept).
  SequenceStep push(StreamFrame frame);

  /// @brief Forgets the previous frame, result and tracks. Ids keep increasing: the next sequence's segments
  /// are numbered from nextId() on, above every id handed out before, so a new segment never continues the
  /// track (or the nodelet's TF frame) of an earlier, unrelated one.
  void reset();
  /// @brief A new solver for the following pairs (parameters changed); the sequence continues. ConfigError for a bad
  /// config (the solver is kept); a backend that cannot be made falls back to the CPU as in the constructor.
  void setConfig(const Config& config);

  /// @brief The optional output images of the following pairs' results (Solver::setOutputs; all by default): a caller
  /// that publishes them only to subscribers asks for them per pair. Kept across setConfig and the CPU fallback.
  void setOutputs(const OutputSelection& selection);

  const Solver& solver() const { return *solver_; }
  /// @brief Tracks of the segments alive after the last solved pair, by id.
  const std::map<int, SegmentTrack>& tracks() const { return tracks_; }
  /// @brief The camera's odometry after the last solved pair (identity before any).
  const Odometry& odometry() const { return odometry_; }
  long pairsSolved() const { return pairs_solved_; }
  /// @brief The id the next new segment gets: above every id of every pair solved so far, across resets.
  int nextId() const { return next_id_; }
  long resets() const { return resets_; }
  /// @brief How often a BackendError moved the pipeline to the CPU (SequenceStep::backend_fallback).
  long backendFallbacks() const { return backend_fallbacks_; }
  /// @brief Why the current solver runs on the CPU although another backend was requested: the BackendError of making
  /// that backend in the constructor or the last setConfig (e.g. "CUDA backend requested but unavailable: CUDA device 7
  /// requested (cuda_device), but 2 CUDA devices are present (0..1)"); empty when the requested backend was made.
  const std::string& backendUnavailable() const { return backend_unavailable_; }

 private:
  PreparedFrame prepare(StreamFrame frame) const;
  void updateTracks(const Result& result);
  void updateOdometry(const Result& result, double interval_s, double stamp);
  // A solver on a backend from the factory; `why`, when given, replaces the factory's note (Result::backend_note). A
  // BackendError of the factory gives a CPU solver and sets `unavailable` to its text (else clears it).
  std::unique_ptr<Solver> makeSolver(const Config& config, std::string* unavailable, const std::string& why = "");

  Config config_;
  OutputSelection outputs_;
  int downsample_request_ = 0;
  double max_pair_interval_ = 1.0;
  SolveBackendFactory make_backend_;
  std::unique_ptr<Solver> solver_;
  std::unique_ptr<PreparedFrame> pair_first_;      // the last solved pair's first frame
  std::unique_ptr<PreparedFrame> previous_frame_;  // the next pair's first frame
  std::unique_ptr<Result> last_result_;            // the prior of the next pair (only while it ends at previous_frame_)
  std::map<int, SegmentTrack> tracks_;
  Odometry odometry_;
  int next_id_ = 1;  // above every id handed out: a pair solved without a prior is numbered from here
  long pairs_solved_ = 0, resets_ = 0, backend_fallbacks_ = 0;
  std::string backend_unavailable_;  // backendUnavailable()
};

std::string toString(SequenceStep::Outcome outcome);

/// @brief Pixels of moving segments (WorldVelocity::moving, one per segment of `result`) in `result.labels`: 255, else
/// 0 (input resolution). Throws InputError when the counts differ.
ImageU8 movingMask(const Result& result, const std::vector<WorldVelocity>& world);
/// @brief movingMask into caller memory: `mask` holds result.labels' pixel count bytes (a ROS image's data, say).
void movingMaskInto(const Result& result, const std::vector<WorldVelocity>& world, std::uint8_t* mask);

}  // namespace mc_flow
