/**
 * @file node_status.h
 * @brief What the nodelet reports about its work: counters of solved, dropped and skipped frames, the backend and its
 * failures, the last stage timings, and throttled warnings (one key per distinct problem). Filled by the worker and the
 * callbacks, read by the diagnostics; thread-safe; times are passed in, so that it is unit-tested without a node
 * (test/ros/test_node_status.cpp).
 */
#pragma once

#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <diagnostic_updater/DiagnosticStatusWrapper.h>
#include <ros/time.h>

#include "mc_flow/core/sequence.h"
#include "mc_flow/core/solver.h"

namespace mc_flow_ros {

class InputGate;

/// A warning a pipeline step calls for: shown through NodeStatus::warning with this key and period.
struct StepWarning {
  std::string key, text;
  double period = 5.0;
};

class NodeStatus {
 public:
  /// @brief A warning of kind `key` (one key per distinct problem; its kind is the key up to the first ':'). Returns
  /// the text to log, or nothing while the key was shown less than `period` seconds ago; the next text shown says how
  /// many were held back since. Every call is counted per kind and remembered as the last problem.
  std::optional<std::string> warning(const std::string& key, const std::string& text, ros::WallTime now,
                                     double period = 5.0);

  void frameDropped();
  void frameSkipped();
  void sequenceReset();
  /// The GPU failed and the pipeline continues on the CPU (`problem`: the failure).
  void backendFailed(const std::string& problem);
  /// A pair was solved in `solve_ms` (the whole push, preparation included).
  void pairSolved(const mc_flow::Result& result, double solve_ms);
  /// @brief Counts what SequencePipeline::push did with the frame stamped `stamp` (a reset, a repeated stamp, a failed
  /// pair, a GPU failure and the move to the CPU, a solved pair taking `solve_ms`) and returns the warnings it calls
  /// for, in words a user can act on.
  std::vector<StepWarning> recordStep(const mc_flow::SequenceStep& step, const std::string& stamp, double solve_ms);
  long framesDropped() const;
  long pairsSolved() const;

  /// @brief The nodelet's diagnostics: the summary (idle, no input, on the CPU after a GPU failure, running), the
  /// input's part (InputGate::addTo) and this one's.
  void fill(diagnostic_updater::DiagnosticStatusWrapper& status, const InputGate& input, bool subscribed,
            ros::WallTime now, double warn_after) const;

 private:
  struct Throttle {
    ros::WallTime last_shown;
    long held_back = 0;  // since last_shown
  };
  mutable std::mutex mutex_;
  long frames_dropped_ = 0, frames_skipped_ = 0, pairs_solved_ = 0, sequence_resets_ = 0;
  long warm_starts_ = 0, cold_fallbacks_ = 0;  // pairs by Result::start (the rest started cold)
  std::string last_start_;                     // the last pair's start kind and, for a fallback, why
  mc_flow::StageTimings last_timings_;
  double total_solve_ms_ = 0;
  std::string backend_, backend_note_, last_problem_;
  long backend_fallbacks_ = 0;
  std::string last_backend_failure_;
  bool on_cpu_after_failure_ = false;  // until a pair is solved on the GPU again
  std::map<std::string, Throttle> throttles_;
  std::map<std::string, long> warnings_per_kind_;
};

}  // namespace mc_flow_ros
