// Frames of the synthetic stream (renderSyntheticFrame) as a SequencePipeline takes them, for the stream tests.
#pragma once

#include "mc_flow/core/sequence.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace mc_flow {
namespace test {

/// Frame t of the 160x120 synthetic sequence of `variant` (with its events: a box that starts moving, one that leaves
/// the view), stamped `stamp`, source "camera", `extra` = t.
inline StreamFrame syntheticStreamFrame(int t, double stamp, int variant = 0) {
  SyntheticSceneOptions o;
  o.width = 160;
  o.height = 120;
  o.variant = variant;
  o.stream_events = true;
  StreamFrame f;
  ImageU8 colour;
  renderSyntheticFrame(o, t, f.frame, colour, f.K);
  f.stamp = stamp;
  f.source = "camera";
  f.extra = t;
  return f;
}

}  // namespace test
}  // namespace mc_flow
