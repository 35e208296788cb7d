/**
 * @file synthetic_scene.h
 * @brief The project's own synthetic RGB-D scenes with known motion (no files, no OpenCV).
 *
 * A textured room (static background), independent rigid objects and one articulated arm whose
 * elbow blends the two links' motions smoothly; rendered by ray casting with a z-buffer so that
 * occlusions, disocclusions and out-of-view points are exact.
 *
 * Library mc_flow_eval (installed; Eigen and the core only): `mcflow demo` / `synth`, the demo bag
 * (make_synthetic_bag), the benchmarks and the tests.
 */
#pragma once

#include <string>
#include <vector>

#include "mc_flow/core/image.h"
#include "mc_flow/core/se3.h"

namespace mc_flow {

struct SyntheticSceneOptions {
  int width = 320;
  int height = 240;
  int variant = 0;               ///< 0..N-1 selects a scene layout/motion set (see syntheticVariantCount())
  double motion_scale = 1.0;     ///< scales every twist
  double intensity_noise = 0.0;  ///< std dev added to intensity (0..1 units)
  double depth_noise = 0.0;      ///< [m] std dev at 1 m, growing with depth^2 (Kinect-like)
  unsigned seed = 1;             ///< noise seed
  /// @brief The tools' --noise: Kinect-like sensor noise, intensity std 0.01 (about 2.5 grey levels) and depth 1.5 mm
  /// at 1 m.
  void addSensorNoise() {
    intensity_noise = 0.01;
    depth_noise = 0.0015;
  }
  int first_frame = 0;         ///< renderSyntheticPair renders frames (first_frame, first_frame + 1) of the sequence
  bool stream_events = false;  ///< adds a box that starts moving at frame 10 (part 10) and one that moves straight
                               ///< out of the view (part 11), for sequences
  /// Nothing in the scene moves, only the camera: every part takes the static scene's apparent motion per
  /// frame, a translation of camera_only_translation_m [m] and a rotation of camera_only_rotation_deg [deg]
  /// about the camera centre (camera frame; the inverse of the camera's own motion), at constant velocity.
  bool camera_only = false;
  Eigen::Vector3d camera_only_translation_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d camera_only_rotation_deg = Eigen::Vector3d::Zero();
  /// Every part (boxes, the arm's links, the stream-event boxes) moves with the room, along the room's own path: the
  /// same camera path over the same geometry and textures, without independently moving parts (variant 2: the
  /// moving camera alone, the baseline of an odometry benchmark). camera_only overrides it.
  bool parts_follow_room = false;
};

struct SyntheticPart {
  int id = 0;  ///< value in SyntheticPair::gt_parts
  std::string name;
  Vector6d twist = Vector6d::Zero();  ///< motion over the pair interval (frame-1 camera frame)
};

/// @brief A rendered pair and its ground truth (all at width x height).
struct SyntheticPair {
  Intrinsics intrinsics;
  RgbdFrame frame1, frame2;
  ImageU8 color1, color2;  ///< 3 channels RGB
  ImageF gt_scene_flow;    ///< 3 channels [m]; NaN where frame 1 has no surface
  ImageF gt_optical_flow;  ///< 2 channels [px]; NaN where frame 1 has no surface
  ImageU8 gt_occlusion;    ///< 255 where the frame-1 point is hidden or out of view in frame 2
  ImageI32 gt_parts;       ///< part id per pixel (0 = static background)
  std::vector<SyntheticPart> parts;
};

int syntheticVariantCount();

/// @brief Where the ray o + lambda d (in the box's frame) enters the box [-h, h]: lambda > 0 and the face
/// 2 * axis + (1 when it enters on the + side); false on a miss or when o is inside. The synthetic scenes' ray cast,
/// shared with other renderers (mcflow_bench_odometry's composited boxes).
bool intersectBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& h, double& lambda,
                  int& face);

/// @brief Renders the pair (first_frame, first_frame + 1) of a variant, with its ground truth.
SyntheticPair renderSyntheticPair(const SyntheticSceneOptions& options);
/// @brief The default scene (variant 0, no noise) at width x height.
inline SyntheticPair renderSyntheticPair(int width, int height) {
  SyntheticSceneOptions options;
  options.width = width;
  options.height = height;
  return renderSyntheticPair(options);
}

/// @brief Renders frame `t` of a smoothly moving sequence (t = 0, 1, 2, ...): the colour, the frame and,
/// when t > 0, nothing else. Consecutive frames t, t+1 form a pair with motion like renderSyntheticPair.
void renderSyntheticFrame(const SyntheticSceneOptions& options, int t, RgbdFrame& frame, ImageU8& color, Intrinsics& K);

/// @brief Ground-truth twists of the parts between frame t and t+1 of the sequence.
std::vector<SyntheticPart> syntheticSequenceMotions(const SyntheticSceneOptions& options, int t);

}  // namespace mc_flow
