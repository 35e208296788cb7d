/**
 * @file synthetic_scene.cpp
 * @brief Ray-cast synthetic RGB-D scenes with exact ground truth (see mc_flow/eval/synthetic_scene.h; library
 * mc_flow_eval, not part of the core).
 *
 * Geometry (camera optical frame of frame 0, metres): a closed room (walls, floor, ceiling; a window in the
 * back wall through which nothing is seen, so depth is invalid there), rigid boxes and one articulated arm.
 * Every primitive is an oriented box; a pixel's ray is transformed into each primitive's own frame and
 * intersected analytically, and the nearest hit wins (an exact z-buffer).
 *
 * Motion: part k has a camera-frame twist xi_k and pose(t) = exp(f_k(t) xi_k) pose(0) with
 * f_k(t) = sin(w_k t) / sin(w_k), so f(0) = 0, f(1) = 1 (the pair moves by exactly exp(xi_k)) and the
 * motion between t and t+1 is exactly exp((f(t+1) - f(t)) xi_k) (same-twist exponentials commute).
 * The arm is one straight bar whose rest-frame point p has the weight s(p) = smoothstep along the bar
 * around the elbow; its position at time t is exp(f(t) ((1 - s) xi_a + s xi_b)) P0(p), i.e. MC-Flow's
 * motion-interpolation model with the upper arm (s = 0) and forearm (s = 1) as rigid links. The deformed
 * bar is ray cast by a fixed-point iteration on s (transform the ray with the motion of the current s,
 * intersect the rest box, update s from the hit), which converges fast because s varies slowly.
 *
 * Textures are functions of each surface's own coordinates (metres), so they move with the surface and
 * brightness constancy holds exactly.
 */
#include "mc_flow/eval/synthetic_scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "mc_flow/core/error.h"

namespace mc_flow {
namespace {

using Eigen::Matrix3d;
using Eigen::Matrix4d;
using Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr double kInf = std::numeric_limits<double>::infinity();

// Default camera (62.5 deg horizontal field of view at 320 x 240); other sizes scale it.
constexpr double kBaseWidth = 320.0, kBaseHeight = 240.0;
constexpr double kBaseFocal = 263.7, kBaseCx = 159.5, kBaseCy = 119.5;

// A frame-1 point counts as occluded when frame 2 sees a surface more than this much in front of it [m].
constexpr double kOcclusionMargin = 0.01;

// ------------------------------------------------------------------------------------------- textures

std::uint32_t hashInts(std::int32_t x, std::int32_t y, std::uint32_t seed) {
  std::uint32_t h = seed * 0x9E3779B1u;
  h ^= static_cast<std::uint32_t>(x) * 0x85EBCA77u;
  h = (h << 13) | (h >> 19);
  h ^= static_cast<std::uint32_t>(y) * 0xC2B2AE3Du;
  h ^= h >> 16;
  h *= 0x7FEB352Du;
  h ^= h >> 15;
  h *= 0x846CA68Bu;
  h ^= h >> 16;
  return h;
}

double unitHash(std::uint32_t seed, std::uint32_t salt) {
  return hashInts(static_cast<std::int32_t>(salt), 0x5bd1e995, seed) * (1.0 / 4294967296.0);
}

double smoothstep01(double q) {
  q = std::clamp(q, 0.0, 1.0);
  return q * q * (3.0 - 2.0 * q);
}

/// Value noise in [0, 1] with quintic fades (C2), one lattice cell per unit of (u, v).
double valueNoise(double u, double v, std::uint32_t seed) {
  const double fu = std::floor(u), fv = std::floor(v);
  const auto iu = static_cast<std::int32_t>(fu), iv = static_cast<std::int32_t>(fv);
  const double a = u - fu, b = v - fv;
  const double wa = a * a * a * (a * (a * 6.0 - 15.0) + 10.0);
  const double wb = b * b * b * (b * (b * 6.0 - 15.0) + 10.0);
  constexpr double kScale = 1.0 / 4294967296.0;
  const double v00 = hashInts(iu, iv, seed) * kScale, v10 = hashInts(iu + 1, iv, seed) * kScale;
  const double v01 = hashInts(iu, iv + 1, seed) * kScale, v11 = hashInts(iu + 1, iv + 1, seed) * kScale;
  const double top = v00 + wa * (v10 - v00), bottom = v01 + wa * (v11 - v01);
  return top + wb * (bottom - top);
}

struct Rgb {
  double r = 0, g = 0, b = 0;
};

Rgb lerp(const Rgb& p, const Rgb& q, double w) {
  return {p.r + w * (q.r - p.r), p.g + w * (q.g - p.g), p.b + w * (q.b - p.b)};
}

/// Colour of surface `seed` at its own coordinates (u, v) [m]; every channel in [0.105, 0.895].
/// Several scales: value-noise octaves (22 cm down to ~2.5 cm cells), sine stripes (6-14 cm period) and
/// blobs of an accent colour, so that flow has texture at every pyramid level.
Rgb surfaceColour(std::uint32_t seed, double u, double v) {
  const Rgb base_a{unitHash(seed, 1), unitHash(seed, 2), unitHash(seed, 3)};
  const Rgb base_b{std::fmod(base_a.r + 0.35 + 0.3 * unitHash(seed, 4), 1.0),
                   std::fmod(base_a.g + 0.35 + 0.3 * unitHash(seed, 5), 1.0),
                   std::fmod(base_a.b + 0.35 + 0.3 * unitHash(seed, 6), 1.0)};
  const Rgb accent{unitHash(seed, 7), unitHash(seed, 8), unitHash(seed, 9)};

  double cell = 0.22, amplitude = 1.0, sum = 0.0, norm = 0.0;
  for (int octave = 0; octave < 4; ++octave) {
    sum += amplitude * valueNoise(u / cell + 17.3 * octave, v / cell - 9.1 * octave, seed + 101u * octave);
    norm += amplitude;
    amplitude *= 0.6;
    cell /= 2.1;
  }
  const double noise = std::clamp(0.5 + 2.2 * (sum / norm - 0.5), 0.0, 1.0);

  const double angle = kPi * unitHash(seed, 10), period = 0.06 + 0.08 * unitHash(seed, 11);
  const double stripe = 0.5 + 0.5 * std::sin(2.0 * kPi * (u * std::cos(angle) + v * std::sin(angle)) / period);
  const double blob = smoothstep01((valueNoise(u / 0.12 + 3.7, v / 0.12 - 5.3, seed ^ 0xB10Bu) - 0.6) / 0.12);

  Rgb c = lerp(lerp(base_a, base_b, noise), accent, 0.85 * blob);
  const double brightness = 0.65 + 0.35 * stripe;
  auto finish = [brightness](double x) { return 0.105 + 0.79 * std::clamp(x * brightness, 0.0, 1.0); };
  return {finish(c.r), finish(c.g), finish(c.b)};
}

/// What is seen through the window (no surface, depth invalid).
constexpr Rgb kSkyColour{0.72, 0.82, 0.89};

// ------------------------------------------------------------------------------------------- scene specs

struct BoxSpec {
  std::string name;
  int part_id = 0;
  Vector3d centre, half_extents;  ///< [m], camera frame of frame 0
  Vector3d rotation_deg;          ///< rotations about x, y, z [deg], applied x first
  Vector3d velocity_m;            ///< translation of the centre per pair [m]
  Vector3d rotation_rate_deg;     ///< rotation about the centre per pair [deg]
  double period = 40.0;           ///< oscillation period of the sequence [frames]; 0 = straight on (f(t) = t)
  int start_frame = 0;            ///< the box rests until this frame
};

struct ArmSpec {
  int upper_id = 0, fore_id = 0;
  Vector3d centre, half_extents;  ///< the bar runs along its local x axis
  Vector3d rotation_deg;
  double elbow_x = 0.0;        ///< elbow position along the bar [m], local x
  double blend_length = 0.2;   ///< length of the transition zone [m]
  Vector3d velocity_m;         ///< shoulder translation per pair [m]
  Vector3d rotation_rate_deg;  ///< upper-arm rotation about the shoulder [deg]
  Vector3d elbow_rate_deg;     ///< extra forearm rotation about the elbow [deg]
  double period = 40.0;
};

struct RoomSpec {
  Vector3d min_corner, max_corner;                    ///< room box in the frame-0 camera frame [m]
  double window_x0, window_x1, window_y0, window_y1;  ///< hole in the back wall (z = max z) [m]
  Vector3d velocity_m = Vector3d::Zero();             ///< apparent background motion per pair (camera ego-motion)
  Vector3d rotation_rate_deg = Vector3d::Zero();      ///< about the camera centre
  double period = 40.0;
};

struct VariantSpec {
  RoomSpec room;
  std::vector<BoxSpec> boxes;
  ArmSpec arm;
  std::uint32_t texture_seed = 0;
};

Matrix3d rotationFromDegrees(const Vector3d& deg) {
  return (Eigen::AngleAxisd(deg.z() * kDeg, Vector3d::UnitZ()) * Eigen::AngleAxisd(deg.y() * kDeg, Vector3d::UnitY()) *
          Eigen::AngleAxisd(deg.x() * kDeg, Vector3d::UnitX()))
      .toRotationMatrix();
}

Matrix4d poseFrom(const Vector3d& centre, const Vector3d& rotation_deg) {
  Matrix4d T = Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = rotationFromDegrees(rotation_deg);
  T.topRightCorner<3, 1>() = centre;
  return T;
}

/// Twist of a translation `velocity` plus a rotation `rate_deg` about the point `pivot` (camera frame).
Vector6d twistAbout(const Vector3d& pivot, const Vector3d& velocity, const Vector3d& rate_deg) {
  const Vector3d w = rate_deg * kDeg;
  Vector6d xi;
  xi.head<3>() = velocity + pivot.cross(w);
  xi.tail<3>() = w;
  return xi;
}

RoomSpec standardRoom() {
  RoomSpec room;
  room.min_corner = Vector3d(-2.0, -1.4, -1.5);
  room.max_corner = Vector3d(2.0, 0.9, 3.6);
  room.window_x0 = 0.7;
  room.window_x1 = 1.5;
  room.window_y0 = -1.25;
  room.window_y1 = -0.55;
  return room;
}

VariantSpec variantSpec(int variant, bool stream_events = false) {
  VariantSpec spec;
  spec.room = standardRoom();
  spec.texture_seed = 7919u * static_cast<std::uint32_t>(variant + 1);
  auto box = [](std::string name, int id, Vector3d c, Vector3d h, Vector3d rot, Vector3d vel, Vector3d rate,
                double period) {
    BoxSpec b;
    b.name = std::move(name);
    b.part_id = id;
    b.centre = c;
    b.half_extents = h;
    b.rotation_deg = rot;
    b.velocity_m = vel;
    b.rotation_rate_deg = rate;
    b.period = period;
    return b;
  };
  ArmSpec& arm = spec.arm;
  arm.half_extents = Vector3d(0.42, 0.05, 0.045);
  arm.blend_length = 0.22;
  arm.elbow_x = 0.0;
  if (variant == 1) {
    // Closer objects that overlap each other (object-object occlusions), faster rotations.
    spec.boxes.push_back(
        box("box", 1, {0.42, 0.12, 1.6}, {0.16, 0.14, 0.1}, {15, -30, 10}, {-0.03, -0.01, 0.02}, {2.0, -3.0, 1.2}, 24));
    spec.boxes.push_back(box("panel", 2, {0.1, 0.02, 2.45}, {0.34, 0.26, 0.03}, {-5, 15, 4}, {0.02, 0.015, -0.025},
                             {1.0, 2.0, -3.0}, 30));
    spec.boxes.push_back(box("cube", 3, {-0.72, 0.3, 2.1}, {0.11, 0.11, 0.11}, {30, 40, 0}, {0.015, -0.02, -0.01},
                             {-2.5, 1.5, 2.5}, 22));
    arm.upper_id = 4;
    arm.fore_id = 5;
    arm.centre = Vector3d(-0.35, -0.42, 1.9);
    arm.rotation_deg = Vector3d(0, -15, -14);
    arm.elbow_x = 0.05;
    arm.velocity_m = Vector3d(-0.012, 0.01, 0.015);
    arm.rotation_rate_deg = Vector3d(-1.0, 1.5, -1.5);
    arm.elbow_rate_deg = Vector3d(-0.5, 0.8, 3.5);
    arm.period = 28;
  } else {
    spec.boxes.push_back(
        box("box", 1, {-0.6, 0.1, 2.0}, {0.2, 0.16, 0.12}, {-12, 28, 6}, {0.025, -0.012, 0.018}, {1.5, 3.0, -1.2}, 28));
    spec.boxes.push_back(box("slab", 2, {0.62, 0.28, 2.4}, {0.26, 0.2, 0.035}, {8, -20, -10}, {-0.03, 0.008, -0.02},
                             {-2.0, 1.2, 2.5}, 24));
    arm.upper_id = 3;
    arm.fore_id = 4;
    arm.centre = Vector3d(0.05, -0.45, 1.75);
    arm.rotation_deg = Vector3d(0, 10, 18);
    arm.velocity_m = Vector3d(0.01, 0.015, -0.01);
    arm.rotation_rate_deg = Vector3d(1.0, -1.5, 2.0);
    arm.elbow_rate_deg = Vector3d(0.5, 1.0, -3.5);
    arm.period = 26;
    if (variant == 2) {
      // The camera moves: the whole room moves rigidly in the camera frame (rotation about the camera centre).
      spec.room.velocity_m = Vector3d(0.015, -0.006, 0.02);
      spec.room.rotation_rate_deg = Vector3d(0.4, -1.0, 0.3);
      spec.room.period = 32;
    }
  }
  if (stream_events) {
    // A box that rests until frame 10 and then moves, and a box that moves straight on out of the view.
    BoxSpec late = box("late_box", 10, {-0.25, 0.5, 2.7}, {0.15, 0.12, 0.1}, {10, 20, 0}, {0.02, -0.015, -0.02},
                       {2.0, -2.5, 1.5}, 30);
    late.start_frame = 10;
    spec.boxes.push_back(late);
    spec.boxes.push_back(
        box("leaver", 11, {0.35, -0.08, 2.2}, {0.1, 0.08, 0.08}, {0, 25, 10}, {0.055, 0.0, 0.0}, {0, 0, 0}, 0));
  }
  return spec;
}

/// Every box and the arm (both links) take the room's motion and path: rigid with the room from frame 0.
void followRoom(VariantSpec& spec) {
  const Vector3d v = spec.room.velocity_m, rate = spec.room.rotation_rate_deg, w = rate * kDeg;
  // A part's twist is taken about its own pivot (twistAbout): the velocity there that gives the room's twist.
  for (BoxSpec& b : spec.boxes) {
    b.velocity_m = v - b.centre.cross(w);
    b.rotation_rate_deg = rate;
    b.period = spec.room.period;
    b.start_frame = 0;
  }
  ArmSpec& arm = spec.arm;
  const Matrix4d arm_pose = poseFrom(arm.centre, arm.rotation_deg);
  const Vector3d shoulder = (arm_pose * Eigen::Vector4d(-arm.half_extents.x(), 0, 0, 1)).head<3>();
  arm.velocity_m = v - shoulder.cross(w);
  arm.rotation_rate_deg = rate;
  arm.elbow_rate_deg = Vector3d::Zero();
  arm.period = spec.room.period;
}

/// Camera-only scenes: the room, every box and the arm (both links) take one motion, the static scene's apparent
/// motion, at constant velocity from frame 0. Scenes whose parts follow the room keep the room's own motion.
void applyCameraOnly(const SyntheticSceneOptions& options, VariantSpec& spec) {
  if (options.camera_only) {
    spec.room.velocity_m = options.camera_only_translation_m;
    spec.room.rotation_rate_deg = options.camera_only_rotation_deg;
    spec.room.period = 0;
  }
  if (options.camera_only || options.parts_follow_room) followRoom(spec);
}

VariantSpec sceneSpec(const SyntheticSceneOptions& options) {
  VariantSpec spec = variantSpec(options.variant, options.stream_events);
  applyCameraOnly(options, spec);
  return spec;
}

// ------------------------------------------------------------------------------------------- motions

/// f(t) = sin(w t) / sin(w): f(0) = 0, f(1) = 1, bounded, so parts stay in view over long sequences; a
/// period of 0 moves straight on (f(t) = t). A part that starts at frame t0 rests before and runs f(t - t0).
double trajectoryFactor(double period, int t, int start_frame = 0) {
  const double s = std::max(0, t - start_frame);
  if (period <= 0) return s;
  const double w = 2.0 * kPi / period;
  return std::sin(w * s) / std::sin(w);
}

/// Camera-frame twists of every part over the pair interval (motion_scale applied).
struct SceneMotion {
  Vector6d background = Vector6d::Zero();
  std::vector<Vector6d> boxes;
  Vector6d upper_arm = Vector6d::Zero(), forearm = Vector6d::Zero();
};

SceneMotion sceneMotion(const VariantSpec& spec, double scale) {
  SceneMotion m;
  m.background.head<3>() = spec.room.velocity_m;
  m.background.tail<3>() = spec.room.rotation_rate_deg * kDeg;
  m.background *= scale;
  for (const BoxSpec& b : spec.boxes) {
    m.boxes.push_back(scale * twistAbout(b.centre, b.velocity_m, b.rotation_rate_deg));
  }
  const Matrix4d arm_pose = poseFrom(spec.arm.centre, spec.arm.rotation_deg);
  const Vector3d shoulder = (arm_pose * Eigen::Vector4d(-spec.arm.half_extents.x(), 0, 0, 1)).head<3>();
  const Vector3d elbow = (arm_pose * Eigen::Vector4d(spec.arm.elbow_x, 0, 0, 1)).head<3>();
  m.upper_arm = scale * twistAbout(shoulder, spec.arm.velocity_m, spec.arm.rotation_rate_deg);
  m.forearm = m.upper_arm + scale * twistAbout(elbow, Vector3d::Zero(), spec.arm.elbow_rate_deg);
  return m;
}

// ------------------------------------------------------------------------------------------- ray casting

/// Maps rays from the camera centre into a primitive's local frame.
struct LocalRayFrame {
  Matrix3d local_R_cam = Matrix3d::Identity();
  Vector3d camera_in_local = Vector3d::Zero();

  static LocalRayFrame fromPose(const Matrix4d& cam_from_local) {
    LocalRayFrame f;
    f.local_R_cam = cam_from_local.topLeftCorner<3, 3>().transpose();
    f.camera_in_local = -f.local_R_cam * cam_from_local.topRightCorner<3, 1>();
    return f;
  }
};

enum class SurfaceKind { kNone, kRoom, kBox, kArm };

struct Hit {
  double depth = kInf;  ///< ray parameter = Z [m] (ray directions have z = 1)
  SurfaceKind kind = SurfaceKind::kNone;
  int box_index = -1;
  int part_id = 0;
  std::uint32_t texture_seed = 0;
  double u = 0, v = 0;  ///< texture coordinates on the surface [m]
  double blend = 0;     ///< arm weight s (0 = upper arm, 1 = forearm)
};

/// Texture coordinates on face `face` of a box or room: the two local coordinates other than the normal.
void faceCoordinates(const Vector3d& p, int face, double& u, double& v) {
  const int axis = face / 2;
  u = p[(axis + 1) % 3];
  v = p[(axis + 2) % 3];
}

/// A variant at time t: every primitive's pose.
class PosedScene {
 public:
  PosedScene(const VariantSpec& spec, const SceneMotion& motion, int t) : spec_(spec), motion_(motion) {
    room_ = LocalRayFrame::fromPose(se3Exp(trajectoryFactor(spec.room.period, t) * motion.background));
    for (std::size_t k = 0; k < spec.boxes.size(); ++k) {
      const BoxSpec& b = spec.boxes[k];
      boxes_.push_back(LocalRayFrame::fromPose(se3Exp(trajectoryFactor(b.period, t, b.start_frame) * motion.boxes[k]) *
                                               poseFrom(b.centre, b.rotation_deg)));
    }
    arm_factor_ = trajectoryFactor(spec.arm.period, t);
    arm_rest_ = poseFrom(spec.arm.centre, spec.arm.rotation_deg);
    for (int i = 0; i < 3; ++i) arm_cached_[i] = armFrameUncached(0.5 * i);
  }

  /// Nearest surface along the ray lambda * d (d.z() == 1), or kind == kNone.
  Hit cast(const Vector3d& d) const {
    Hit best;
    castRoom(d, best);
    for (std::size_t k = 0; k < boxes_.size(); ++k) castBox(static_cast<int>(k), d, best);
    castArm(d, best);
    return best;
  }

  /// Arm weight s at local (rest-frame) bar coordinate x.
  double armWeight(double x) const {
    return smoothstep01((x - (spec_.arm.elbow_x - 0.5 * spec_.arm.blend_length)) / spec_.arm.blend_length);
  }

 private:
  void castRoom(const Vector3d& d, Hit& best) const {
    const Vector3d o = room_.camera_in_local, dl = room_.local_R_cam * d;
    const Vector3d& lo = spec_.room.min_corner;
    const Vector3d& hi = spec_.room.max_corner;
    // The camera is inside the room: the visible wall is where the ray leaves the box.
    double t_exit = kInf;
    int face = -1;
    for (int i = 0; i < 3; ++i) {
      if (dl[i] == 0.0) continue;
      const double t = ((dl[i] > 0.0 ? hi[i] : lo[i]) - o[i]) / dl[i];
      if (t < t_exit) {
        t_exit = t;
        face = 2 * i + (dl[i] > 0.0 ? 1 : 0);
      }
    }
    if (face < 0 || !(t_exit > 0.0) || t_exit >= best.depth) return;
    const Vector3d p = o + t_exit * dl;
    if (face == 5 && p.x() > spec_.room.window_x0 && p.x() < spec_.room.window_x1 && p.y() > spec_.room.window_y0 &&
        p.y() < spec_.room.window_y1) {
      return;  // through the window: nothing to measure
    }
    best.depth = t_exit;
    best.kind = SurfaceKind::kRoom;
    best.part_id = 0;
    best.box_index = -1;
    best.texture_seed = spec_.texture_seed + 100u + static_cast<std::uint32_t>(face);
    faceCoordinates(p, face, best.u, best.v);
  }

  void castBox(int k, const Vector3d& d, Hit& best) const {
    const LocalRayFrame& f = boxes_[k];
    const Vector3d dl = f.local_R_cam * d;
    double lambda;
    int face;
    if (!intersectBox(f.camera_in_local, dl, spec_.boxes[k].half_extents, lambda, face) || lambda >= best.depth) {
      return;
    }
    const Vector3d p = f.camera_in_local + lambda * dl;
    best.depth = lambda;
    best.kind = SurfaceKind::kBox;
    best.box_index = k;
    best.part_id = spec_.boxes[k].part_id;
    best.texture_seed =
        spec_.texture_seed + 1000u + 16u * static_cast<std::uint32_t>(k) + static_cast<std::uint32_t>(face);
    faceCoordinates(p, face, best.u, best.v);
  }

  LocalRayFrame armFrameUncached(double s) const {
    const Vector6d xi = arm_factor_ * ((1.0 - s) * motion_.upper_arm + s * motion_.forearm);
    return LocalRayFrame::fromPose(se3Exp(xi) * arm_rest_);
  }

  LocalRayFrame armFrame(double s) const {
    if (s == 0.0) return arm_cached_[0];
    if (s == 0.5) return arm_cached_[1];
    if (s == 1.0) return arm_cached_[2];
    return armFrameUncached(s);
  }

  /// Fixed point s = s(p(s)) from three starting weights; the nearest converged hit is the visible one.
  void castArm(const Vector3d& d, Hit& best) const {
    constexpr int kMaxIterations = 40;
    constexpr double kTolerance = 1e-11;
    const Vector3d& h = spec_.arm.half_extents;
    for (double start : {0.0, 1.0, 0.5}) {
      double s = start;
      for (int it = 0; it < kMaxIterations; ++it) {
        const LocalRayFrame f = armFrame(s);
        const Vector3d dl = f.local_R_cam * d;
        double lambda;
        int face;
        if (!intersectBox(f.camera_in_local, dl, h, lambda, face)) break;
        const Vector3d p = f.camera_in_local + lambda * dl;
        const double s_next = armWeight(p.x());
        if (std::abs(s_next - s) <= kTolerance) {
          if (lambda < best.depth) {
            best.depth = lambda;
            best.kind = SurfaceKind::kArm;
            best.box_index = -1;
            best.blend = s;
            best.part_id = s < 0.5 ? spec_.arm.upper_id : spec_.arm.fore_id;
            best.texture_seed = spec_.texture_seed + 2000u + static_cast<std::uint32_t>(face);
            faceCoordinates(p, face, best.u, best.v);
          }
          break;
        }
        s = s_next;
      }
    }
  }

  const VariantSpec& spec_;
  const SceneMotion& motion_;
  LocalRayFrame room_;
  std::vector<LocalRayFrame> boxes_;
  double arm_factor_ = 0.0;
  Matrix4d arm_rest_ = Matrix4d::Identity();
  std::array<LocalRayFrame, 3> arm_cached_;
};

// ------------------------------------------------------------------------------------------- rendering

void validateOptions(const SyntheticSceneOptions& o) {
  if (o.width < 16 || o.width > 8192 || o.height < 16 || o.height > 8192) {
    throw InputError("synthetic scene: size " + std::to_string(o.width) + "x" + std::to_string(o.height) +
                     " outside [16, 8192]");
  }
  if (o.variant < 0 || o.variant >= syntheticVariantCount()) {
    throw InputError("synthetic scene: variant " + std::to_string(o.variant) + " outside [0, " +
                     std::to_string(syntheticVariantCount() - 1) + "]");
  }
  if (!std::isfinite(o.motion_scale) || std::abs(o.motion_scale) > 20.0) {
    throw InputError("synthetic scene: motion_scale " + std::to_string(o.motion_scale) + " not in [-20, 20]");
  }
  if (!std::isfinite(o.intensity_noise) || o.intensity_noise < 0.0) {
    throw InputError("synthetic scene: intensity_noise " + std::to_string(o.intensity_noise) + " must be >= 0");
  }
  if (o.first_frame < 0 || o.first_frame > 100000) {
    throw InputError("synthetic scene: first_frame " + std::to_string(o.first_frame) + " outside [0, 100000]");
  }
  if (!std::isfinite(o.depth_noise) || o.depth_noise < 0.0) {
    throw InputError("synthetic scene: depth_noise " + std::to_string(o.depth_noise) + " must be >= 0");
  }
  if (!o.camera_only_translation_m.allFinite() || o.camera_only_translation_m.norm() > 1.0 ||
      !o.camera_only_rotation_deg.allFinite() || o.camera_only_rotation_deg.norm() > 45.0) {
    throw InputError("synthetic scene: camera-only motion (" + std::to_string(o.camera_only_translation_m.norm()) +
                     " m, " + std::to_string(o.camera_only_rotation_deg.norm()) +
                     " deg per frame) must be finite, at most 1 m and 45 deg");
  }
}

Intrinsics sceneIntrinsics(int width, int height) {
  const double sx = width / kBaseWidth, sy = height / kBaseHeight;
  return {kBaseFocal * sx, kBaseFocal * sy, (kBaseCx + 0.5) * sx - 0.5, (kBaseCy + 0.5) * sy - 0.5};
}

Vector3d pixelRay(const Intrinsics& K, int x, int y) { return {(x - K.cx) / K.fx, (y - K.cy) / K.fy, 1.0}; }

std::uint8_t toByte(double c) { return static_cast<std::uint8_t>(std::lround(std::clamp(c, 0.0, 1.0) * 255.0)); }

/// Renders frame t; the per-pixel hits are kept when `hits` is given (for the ground truth).
void renderFrame(const SyntheticSceneOptions& options, const VariantSpec& spec, const SceneMotion& motion, int t,
                 RgbdFrame& frame, ImageU8& color, std::vector<Hit>* hits) {
  const int W = options.width, H = options.height;
  const Intrinsics K = sceneIntrinsics(W, H);
  const PosedScene scene(spec, motion, t);
  std::vector<Rgb> colours(std::size_t(W) * H);
  std::vector<double> depths(std::size_t(W) * H);
  if (hits) hits->assign(std::size_t(W) * H, Hit());

#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const std::size_t i = std::size_t(y) * W + x;
      const Hit hit = scene.cast(pixelRay(K, x, y));
      const bool surface = hit.kind != SurfaceKind::kNone;
      colours[i] = surface ? surfaceColour(hit.texture_seed, hit.u, hit.v) : kSkyColour;
      depths[i] = surface ? hit.depth : 0.0;
      if (hits) (*hits)[i] = hit;
    }
  }

  // Noise is drawn in pixel order from one generator per frame, so frames are reproducible on their own.
  std::seed_seq seeds{options.seed, static_cast<unsigned>(t), 0x5CE4Eu};
  std::mt19937 rng(seeds);
  std::normal_distribution<double> normal(0.0, 1.0);
  frame.intensity = ImageF(W, H, 1, 0.f);
  frame.depth = ImageF(W, H, 1, 0.f);
  color = ImageU8(W, H, 3, 0);
  for (std::size_t i = 0; i < colours.size(); ++i) {
    // The same luminance offset on R, G and B adds exactly that offset to the grey value.
    const double n = options.intensity_noise > 0.0 ? options.intensity_noise * normal(rng) : 0.0;
    const std::uint8_t r = toByte(colours[i].r + n), g = toByte(colours[i].g + n), b = toByte(colours[i].b + n);
    color.data[3 * i] = r;
    color.data[3 * i + 1] = g;
    color.data[3 * i + 2] = b;
    frame.intensity.data[i] = static_cast<float>(greyFromRgb(r, g, b) / 255.0);
    double z = depths[i];
    if (z > 0.0 && options.depth_noise > 0.0) z = std::max(0.0, z + options.depth_noise * z * z * normal(rng));
    frame.depth.data[i] = static_cast<float>(z);
  }
}

std::vector<SyntheticPart> partsAt(const VariantSpec& spec, const SceneMotion& motion, int t) {
  std::vector<SyntheticPart> parts;
  auto add = [&parts](int id, const std::string& name, const Vector6d& xi, double period, int tt, int start) {
    SyntheticPart p;
    p.id = id;
    p.name = name;
    p.twist = (trajectoryFactor(period, tt + 1, start) - trajectoryFactor(period, tt, start)) * xi;
    parts.push_back(p);
  };
  add(0, "background", motion.background, spec.room.period, t, 0);
  for (std::size_t k = 0; k < spec.boxes.size(); ++k) {
    add(spec.boxes[k].part_id, spec.boxes[k].name, motion.boxes[k], spec.boxes[k].period, t, spec.boxes[k].start_frame);
  }
  add(spec.arm.upper_id, "upper_arm", motion.upper_arm, spec.arm.period, t, 0);
  add(spec.arm.fore_id, "forearm", motion.forearm, spec.arm.period, t, 0);
  return parts;
}

}  // namespace

int syntheticVariantCount() { return 3; }

void renderSyntheticFrame(const SyntheticSceneOptions& options, int t, RgbdFrame& frame, ImageU8& color,
                          Intrinsics& K) {
  validateOptions(options);
  if (t < 0) throw InputError("synthetic scene: frame index " + std::to_string(t) + " must be >= 0");
  const VariantSpec spec = sceneSpec(options);
  const SceneMotion motion = sceneMotion(spec, options.motion_scale);
  K = sceneIntrinsics(options.width, options.height);
  renderFrame(options, spec, motion, t, frame, color, nullptr);
}

std::vector<SyntheticPart> syntheticSequenceMotions(const SyntheticSceneOptions& options, int t) {
  validateOptions(options);
  if (t < 0) throw InputError("synthetic scene: frame index " + std::to_string(t) + " must be >= 0");
  const VariantSpec spec = sceneSpec(options);
  return partsAt(spec, sceneMotion(spec, options.motion_scale), t);
}

SyntheticPair renderSyntheticPair(const SyntheticSceneOptions& options) {
  validateOptions(options);
  const VariantSpec spec = sceneSpec(options);
  const SceneMotion motion = sceneMotion(spec, options.motion_scale);
  const int W = options.width, H = options.height;
  const int t0 = options.first_frame;

  SyntheticPair pair;
  pair.intrinsics = sceneIntrinsics(W, H);
  const Intrinsics& K = pair.intrinsics;
  std::vector<Hit> hits;
  renderFrame(options, spec, motion, t0, pair.frame1, pair.color1, &hits);
  renderFrame(options, spec, motion, t0 + 1, pair.frame2, pair.color2, nullptr);
  pair.parts = partsAt(spec, motion, t0);

  // Frame-1 -> frame-2 transforms: exp((f(t0 + 1) - f(t0)) xi) per part (exponentials of one twist commute);
  // for the first pair f(1) - f(0) == 1 exactly.
  auto step = [t0](double period, int start) {
    return trajectoryFactor(period, t0 + 1, start) - trajectoryFactor(period, t0, start);
  };
  const Matrix4d background_motion = se3Exp(step(spec.room.period, 0) * motion.background);
  std::vector<Matrix4d> box_motion;
  for (std::size_t k = 0; k < motion.boxes.size(); ++k)
    box_motion.push_back(se3Exp(step(spec.boxes[k].period, spec.boxes[k].start_frame) * motion.boxes[k]));
  const double arm_step = step(spec.arm.period, 0);
  const Matrix4d upper_motion = se3Exp(arm_step * motion.upper_arm), fore_motion = se3Exp(arm_step * motion.forearm);

  const PosedScene scene2(spec, motion, t0 + 1);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  pair.gt_scene_flow = ImageF(W, H, 3, nan);
  pair.gt_optical_flow = ImageF(W, H, 2, nan);
  pair.gt_occlusion = ImageU8(W, H, 1, 0);
  pair.gt_parts = ImageI32(W, H, 1, 0);

#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const Hit& hit = hits[std::size_t(y) * W + x];
      pair.gt_parts(x, y) = hit.part_id;
      if (hit.kind == SurfaceKind::kNone) continue;
      const Vector3d P = hit.depth * pixelRay(K, x, y);
      Matrix4d M;
      switch (hit.kind) {
        case SurfaceKind::kRoom: M = background_motion; break;
        case SurfaceKind::kBox: M = box_motion[hit.box_index]; break;
        default:
          M = hit.blend == 0.0 ? upper_motion
              : hit.blend == 1.0
                  ? fore_motion
                  : se3Exp(arm_step * ((1.0 - hit.blend) * motion.upper_arm + hit.blend * motion.forearm));
      }
      const Vector3d P2 = M.topLeftCorner<3, 3>() * P + M.topRightCorner<3, 1>();
      for (int c = 0; c < 3; ++c) pair.gt_scene_flow(x, y, c) = static_cast<float>(P2[c] - P[c]);
      if (!(P2.z() > 1e-6)) {
        pair.gt_occlusion(x, y) = 255;  // behind the camera: no projection
        continue;
      }
      const double u2 = K.fx * P2.x() / P2.z() + K.cx, v2 = K.fy * P2.y() / P2.z() + K.cy;
      pair.gt_optical_flow(x, y, 0) = static_cast<float>(u2 - x);
      pair.gt_optical_flow(x, y, 1) = static_cast<float>(v2 - y);
      // In view = inside some pixel's footprint.
      if (u2 < -0.5 || u2 >= W - 0.5 || v2 < -0.5 || v2 >= H - 0.5) {
        pair.gt_occlusion(x, y) = 255;
        continue;
      }
      // Exact visibility: cast frame 2's ray through P2 itself.
      const Hit seen = scene2.cast(P2 / P2.z());
      if (seen.kind != SurfaceKind::kNone && seen.depth < P2.z() - kOcclusionMargin) pair.gt_occlusion(x, y) = 255;
    }
  }
  return pair;
}

bool intersectBox(const Vector3d& o, const Vector3d& d, const Vector3d& h, double& lambda, int& face) {
  double t_near = -kInf, t_far = kInf;
  int near_axis = -1;
  for (int i = 0; i < 3; ++i) {
    if (d[i] == 0.0) {
      if (o[i] < -h[i] || o[i] > h[i]) return false;
      continue;
    }
    double t1 = (-h[i] - o[i]) / d[i], t2 = (h[i] - o[i]) / d[i];
    if (t1 > t2) std::swap(t1, t2);
    if (t1 > t_near) {
      t_near = t1;
      near_axis = i;
    }
    t_far = std::min(t_far, t2);
  }
  if (near_axis < 0 || t_near > t_far || t_near <= 0.0) return false;
  lambda = t_near;
  face = 2 * near_axis + (d[near_axis] < 0.0 ? 1 : 0);
  return true;
}

}  // namespace mc_flow
