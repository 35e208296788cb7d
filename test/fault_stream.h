// A synthetic stream pushed through a SequencePipeline, and what each frame's step said: shared by the
// backend-fault tests of test/core (injected faults, any machine) and test/cuda (real CUDA faults).
#pragma once

#include <any>
#include <string>
#include <vector>

#include "mc_flow/core/sequence.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace mc_flow {
namespace test {

/// @brief Frame `t` of synthetic variant 0 (with its stream events) at `width` x `height`, 30 Hz stamps;
/// `extra` holds t.
inline StreamFrame syntheticStreamFrame(int t, int width, int height) {
  SyntheticSceneOptions o;
  o.width = width;
  o.height = height;
  o.stream_events = true;
  StreamFrame f;
  ImageU8 colour;
  renderSyntheticFrame(o, t, f.frame, colour, f.K);
  f.stamp = 100.0 + 0.033 * t;
  f.source = "camera";
  f.extra = t;
  return f;
}

/// @brief Per frame of a stream: the step's outcome and fallback report and, where a pair was solved, the backend
/// that solved it and its note, how it started and the pair's first frame (Auto, "", Cold and -1 where nothing was
/// solved).
struct StreamRun {
  std::vector<SequenceStep::Outcome> outcomes;
  std::vector<std::string> fallbacks;
  std::vector<Backend> backends;
  std::vector<StartKind> starts;
  std::vector<int> first_frames;
  std::vector<std::string> notes;  ///< Result::backend_note

  /// @brief The one frame whose step reported a fallback; -1 for none, -2 for more than one.
  int fallbackFrame() const {
    int frame = -1;
    for (std::size_t t = 0; t < fallbacks.size(); ++t)
      if (!fallbacks[t].empty()) frame = frame == -1 ? int(t) : -2;
    return frame;
  }
};

/// @brief Pushes frames 0 .. frames-1 through `pipeline`.
inline StreamRun runStream(SequencePipeline& pipeline, int frames, int width, int height) {
  StreamRun run;
  for (int t = 0; t < frames; ++t) {
    const SequenceStep step = pipeline.push(syntheticStreamFrame(t, width, height));
    const bool solved = step.outcome == SequenceStep::Outcome::Solved;
    run.outcomes.push_back(step.outcome);
    run.fallbacks.push_back(step.backend_fallback);
    run.backends.push_back(solved ? step.result->backend_kind : Backend::Auto);
    run.starts.push_back(solved ? step.result->start : StartKind::Cold);
    run.first_frames.push_back(solved ? std::any_cast<int>(step.first->extra) : -1);
    run.notes.push_back(solved ? step.result->backend_note : "");
  }
  return run;
}

}  // namespace test
}  // namespace mc_flow
