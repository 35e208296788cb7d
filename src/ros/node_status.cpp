#include "mc_flow/ros/node_status.h"

#include <diagnostic_msgs/DiagnosticStatus.h>

#include "mc_flow/ros/input_gate.h"

namespace mc_flow_ros {

std::optional<std::string> NodeStatus::warning(const std::string& key, const std::string& text, ros::WallTime now,
                                               double period) {
  std::lock_guard<std::mutex> lock(mutex_);
  last_problem_ = text;
  ++warnings_per_kind_[key.substr(0, key.find(':'))];
  Throttle& throttle = throttles_[key];
  if (!throttle.last_shown.isZero() && (now - throttle.last_shown).toSec() < period) {
    ++throttle.held_back;
    return std::nullopt;
  }
  const long held_back = throttle.held_back;
  throttle.last_shown = now;
  throttle.held_back = 0;
  if (held_back == 0) return text;
  return text + " (" + std::to_string(held_back) + " more like this since the last such warning)";
}

void NodeStatus::frameDropped() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++frames_dropped_;
}

void NodeStatus::frameSkipped() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++frames_skipped_;
}

void NodeStatus::sequenceReset() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++sequence_resets_;
}

void NodeStatus::backendFailed(const std::string& problem) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++backend_fallbacks_;
  ++frames_skipped_;  // the pair is lost
  last_backend_failure_ = problem;
  on_cpu_after_failure_ = true;
  backend_ = "cpu";
  backend_note_ = "fallback after a failure of the requested backend";
}

void NodeStatus::pairSolved(const mc_flow::Result& result, double solve_ms) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++pairs_solved_;
  warm_starts_ += result.start == mc_flow::StartKind::Warm ? 1 : 0;
  cold_fallbacks_ += result.start == mc_flow::StartKind::ColdFallback ? 1 : 0;
  last_start_ = mc_flow::toString(result.start) + (result.start_note.empty() ? "" : ": " + result.start_note);
  last_timings_ = result.timings;
  total_solve_ms_ += solve_ms;
  backend_ = result.backend;
  backend_note_ = result.backend_note;
  if (result.backend_kind == mc_flow::Backend::Cuda) on_cpu_after_failure_ = false;  // new parameters restored it
}

std::vector<StepWarning> NodeStatus::recordStep(const mc_flow::SequenceStep& step, const std::string& stamp,
                                                double solve_ms) {
  std::vector<StepWarning> warnings;
  if (!step.reset_key.empty()) {
    warnings.push_back(
        {"reset:" + step.reset_key, "frame " + stamp + ": " + step.reset_reason + ": starting a new sequence"});
    sequenceReset();
  }
  using Outcome = mc_flow::SequenceStep::Outcome;
  switch (step.outcome) {
    case Outcome::Started: break;
    case Outcome::RepeatedStamp:
      warnings.push_back({"stamp", "frame skipped: stamp " + stamp +
                                       " repeats the previous frame's (is a driver or bag publishing duplicates?)"});
      frameSkipped();
      break;
    case Outcome::PairFailed:
      if (!step.backend_fallback.empty()) {
        // The pipeline has switched to the CPU: this happens once per backend, so the warning is never held back
        // (period 0; a GPU restored by new parameters may fail again and is reported again).
        warnings.push_back(
            {"backend", "pair ending at " + stamp + " skipped: " + step.problem + "; continuing on the CPU", 0.0});
        backendFailed(step.problem);
      } else {
        // Bad input or parameters that do not fit this input: the sequence goes on with the newer frame.
        warnings.push_back({"solver", "pair ending at " + stamp + " skipped: " + step.problem});
        frameSkipped();
      }
      break;
    case Outcome::Solved: pairSolved(*step.result, solve_ms); break;
  }
  return warnings;
}

long NodeStatus::framesDropped() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return frames_dropped_;
}

long NodeStatus::pairsSolved() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return pairs_solved_;
}

void NodeStatus::fill(diagnostic_updater::DiagnosticStatusWrapper& status, const InputGate& input, bool subscribed,
                      ros::WallTime now, double warn_after) const {
  const bool silent = subscribed && input.silent(now, warn_after);
  std::lock_guard<std::mutex> lock(mutex_);
  using diagnostic_msgs::DiagnosticStatus;
  if (!subscribed) {
    status.summary(DiagnosticStatus::OK, "idle: no listener on any output");
  } else if (silent) {
    status.summary(DiagnosticStatus::WARN, "no synchronised input");
  } else if (on_cpu_after_failure_) {
    status.summary(DiagnosticStatus::WARN, "running on the CPU after a GPU failure");
  } else {
    status.summary(DiagnosticStatus::OK, "running");
  }
  input.addTo(status, now);
  status.add("pairs solved", pairs_solved_);
  status.add("frames dropped (arrived while solving)", frames_dropped_);
  status.add("frames skipped (bad input)", frames_skipped_);
  status.add("sequence resets", sequence_resets_);
  status.add("pairs started warm", warm_starts_);
  status.add("pairs started cold after a refused warm start", cold_fallbacks_);
  status.add("last start", last_start_.empty() ? std::string("(no pair solved yet)") : last_start_);
  for (const auto& [kind, count] : warnings_per_kind_) status.add("warnings: " + kind, count);
  status.add("solve time mean [ms]", pairs_solved_ > 0 ? total_solve_ms_ / double(pairs_solved_) : 0.0);
  status.add("solve time last [ms]", last_timings_.total);
  status.add("stage preprocessing [ms]", last_timings_.preprocessing);
  status.add("stage initialisation [ms]", last_timings_.initialisation);
  status.add("stage motion [ms]", last_timings_.motion);
  status.add("stage labels [ms]", last_timings_.labels);
  status.add("stage adaptation [ms]", last_timings_.adaptation);
  status.add("stage adaptation: merge test [ms]", last_timings_.merge_test);
  status.add("stage occlusion [ms]", last_timings_.occlusion);
  status.add("stage outputs [ms]", last_timings_.outputs);
  status.add("backend", backend_.empty() ? std::string("(no pair solved yet)") : backend_ + ": " + backend_note_);
  status.add("backend fallbacks (GPU failures)", backend_fallbacks_);
  status.add("last backend failure", last_backend_failure_.empty() ? std::string("none") : last_backend_failure_);
  status.add("last problem", last_problem_.empty() ? std::string("none") : last_problem_);
}

}  // namespace mc_flow_ros
