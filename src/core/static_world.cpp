// The static world of a pair: its segments (a prior's agreement, the stream's memory, or the widest), its motion fitted
// once on their union, and what follows from it (each segment's motion relative to the world). docs/ALGORITHM.md,
// "Static world and odometry".
#include "mc_flow/core/static_world.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_adaptation.h"
#include "mc_flow/core/solver.h"

namespace mc_flow {

Matrix6d twistCovariance(const Matrix6d& curvature, double cost, double pixels, const Config& config) {
  // Too few pixels to say anything (fewer than a twist's six unknowns, or no curvature): a covariance that says so,
  // 1 m and 1 rad, not a zero one that would claim certainty.
  if (!(pixels >= 6.0) || !(curvature.diagonal().maxCoeff() > 0)) return Matrix6d::Identity();
  const double dof = std::max(1.0, 2.0 * pixels - 6.0);
  const double variance = std::max(0.0, cost) / dof;
  const Matrix6d inverse = withRidge(curvature).ldlt().solve(Matrix6d::Identity());
  const Matrix6d covariance = config.world_covariance_scale * variance * inverse;
  return 0.5 * (covariance + covariance.transpose());
}

namespace {
// Fewer depth edges than this between two candidates say nothing about which is in front (pixels of a level about
// 160 pixels wide: a few pixels of noise along a seam).
constexpr double kMinDepthEdges = 20;
// A seam is a depth edge only where its jump is more than this many times the depth step next to it on either side.
constexpr double kSurfaceJump = 3.0;
}  // namespace

double DepthOrder::frontShare(const std::vector<int>& a, const std::vector<int>& b, double& edges) const {
  double nearer = 0;
  edges = 0;
  if (segments < 0 || front.size() != std::size_t(segments) * std::size_t(segments))
    throw InputError("DepthOrder: " + std::to_string(front.size()) + " counts for " + std::to_string(segments) +
                     " segments");
  for (const int i : a)
    for (const int j : b) {
      if (i < 0 || j < 0 || i >= segments || j >= segments) continue;
      nearer += front[std::size_t(i) * std::size_t(segments) + std::size_t(j)];
      edges += front[std::size_t(i) * std::size_t(segments) + std::size_t(j)] +
               front[std::size_t(j) * std::size_t(segments) + std::size_t(i)];
    }
  return edges > 0 ? nearer / edges : 0.0;
}

DepthOrder depthOrderOf(const ImageI32& segment_ids, const std::vector<Segment>& segments, const ImageF& points,
                        int step, double depth_edge) {
  if (points.channels != 3 || step < 1 || (points.width - 1) * step >= segment_ids.width ||
      (points.height - 1) * step >= segment_ids.height)
    throw InputError("depthOrderOf: points of " + std::to_string(points.width) + "x" + std::to_string(points.height) +
                     "x" + std::to_string(points.channels) + " at step " + std::to_string(step) +
                     " do not fit segment ids of " + std::to_string(segment_ids.width) + "x" +
                     std::to_string(segment_ids.height));
  DepthOrder order;
  order.segments = int(segments.size());
  order.front.assign(segments.size() * segments.size(), 0.0);
  const int w = points.width, h = points.height;
  std::vector<int> index(std::size_t(w) * std::size_t(h), -1);
  // Neighbouring pixels mostly share a segment: the last id's index is reused, a new id is looked up among the few
  // segments.
  int last_id = std::numeric_limits<int>::min(), last_index = -1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      // The id at the centre of the block of ids the point stands for.
      const int id = segment_ids(std::min(x * step + step / 2, segment_ids.width - 1),
                                 std::min(y * step + step / 2, segment_ids.height - 1));
      if (id != last_id) {
        last_id = id;
        last_index = -1;
        for (std::size_t i = 0; i < segments.size(); ++i)
          if (segments[i].id == id) last_index = int(i);
      }
      if (last_index >= 0 && std::isfinite(points(x, y, 2))) index[std::size_t(y) * w + x] = last_index;
    }
  // Depth of a point, NaN outside the image (or without depth).
  auto depth = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < w && y < h ? double(points(x, y, 2)) : std::numeric_limits<double>::quiet_NaN();
  };
  // The seam between pixel (x, y) and (x + dx, y + dy): an edge where the jump is larger than depth_edge and than
  // kSurfaceJump times the steps on either side of it (a slanted floor or wall changes depth steadily from pixel to
  // pixel: its seam is no edge).
  auto edge = [&](int x, int y, int dx, int dy) {
    const int a = index[std::size_t(y) * w + x], b = index[std::size_t(y + dy) * w + x + dx];
    if (a < 0 || b < 0 || a == b) return;
    const double za = depth(x, y), zb = depth(x + dx, y + dy);
    const double jump = std::abs(za - zb);
    if (jump <= depth_edge) return;
    const double before = std::abs(depth(x - dx, y - dy) - za), after = std::abs(depth(x + 2 * dx, y + 2 * dy) - zb);
    if ((std::isfinite(before) && jump <= kSurfaceJump * before) ||
        (std::isfinite(after) && jump <= kSurfaceJump * after))
      return;
    const int nearer = za < zb ? a : b, farther = za < zb ? b : a;
    order.front[std::size_t(nearer) * segments.size() + std::size_t(farther)] += 1;
  };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (x + 1 < w) edge(x, y, 1, 0);
      if (y + 1 < h) edge(x, y, 0, 1);
    }
  return order;
}

StaticWorld estimateStaticWorld(LabelStore& labels, const std::vector<Segment>& segments,
                                const std::vector<int>& previous_world_ids, const Eigen::Matrix4d* camera_motion_prior,
                                bool use_occlusion, const Config& config, std::vector<Matrix6d>& segment_covariances,
                                const DepthOrder* depth_order) {
  StaticWorld world;
  const int n = int(segments.size());
  if (n != labels.labelCount() - 1)
    throw InputError("estimateStaticWorld: " + std::to_string(n) + " segments for " +
                     std::to_string(labels.labelCount() - 1) + " motion labels");
  segment_covariances.assign(std::size_t(n), Matrix6d::Zero());
  if (n == 0) return world;
  std::vector<Vector6d> twists;
  for (const Segment& s : segments) twists.push_back(s.twist);
  const LabelCostModel own = labels.costModel(twists, use_occlusion, config);
  for (int i = 0; i < n; ++i)
    segment_covariances[std::size_t(i)] =
        twistCovariance(own.curvature[std::size_t(i)], own.cost[std::size_t(i)], own.pixels[std::size_t(i)], config);
  const int widest = int(std::max_element(own.pixels.begin(), own.pixels.end()) - own.pixels.begin());
  const double noise = own.cost[std::size_t(widest)] / std::max(1.0, own.pixels[std::size_t(widest)]);
  // Whether one motion (the pass `under` of every segment at it) explains segment i's pixels as well as its own motion
  // does: the merge test's rule, against the widest segment's noise level.
  auto explainedBy = [&](const LabelCostModel& under, int i, double tolerance_factor) {
    MergeEvidence e;
    e.own_a = e.own_b = own.cost[std::size_t(i)];
    e.increase_a = e.increase_b = under.cost[std::size_t(i)] - own.cost[std::size_t(i)];
    e.pixels_a = e.pixels_b = own.pixels[std::size_t(i)];
    e.noise_per_pixel = noise;
    return oneMotionExplains(e, tolerance_factor * config.merge_refit_tolerance,
                             tolerance_factor * config.merge_refit_noise_tolerance);
  };
  // Whether group a is in front of group b where they meet (a moving thing in front of the room it moves in).
  auto inFront = [&](const std::vector<int>& a, const std::vector<int>& b) {
    if (!depth_order || depth_order->segments != n || config.world_front_share <= 0) return false;
    double edges = 0;
    const double share = depth_order->frontShare(a, b, edges);
    return edges >= kMinDepthEdges && share > config.world_front_share;
  };

  // 1. A prior: the segments whose pixels the prior's world motion explains as well as their own motions do.
  if (camera_motion_prior) {
    const Vector6d prior_twist = se3Log(Eigen::Matrix4d(camera_motion_prior->inverse()));
    const LabelCostModel under_prior =
        labels.costModel(std::vector<Vector6d>(std::size_t(n), prior_twist), use_occlusion, config);
    for (int i = 0; i < n; ++i) {
      if (own.pixels[std::size_t(i)] < 6.0) continue;  // no evidence either way
      if (explainedBy(under_prior, i, 1.0)) world.labels.push_back(i);
    }
    if (!world.labels.empty()) world.chosen_by = "prior";
  }
  // 2. The stream's memory: the segments that carry an id of the previous pair's world, unless a segment outside them
  // has outgrown them (world_outgrown_ratio): a first pair's world can be a moving thing together with part of the
  // room, whose id the stream would otherwise keep while the room's own segment grows around it.
  if (world.labels.empty() && !previous_world_ids.empty()) {
    double remembered_pixels = 0;
    for (int i = 0; i < n; ++i)
      if (std::find(previous_world_ids.begin(), previous_world_ids.end(), segments[std::size_t(i)].id) !=
          previous_world_ids.end()) {
        world.labels.push_back(i);
        remembered_pixels += own.pixels[std::size_t(i)];
      }
    // A remembered world in front of the widest segment is a thing that moves in front of the room (ids follow
    // labels, and a label can come to hold a box where it held the room); the room is behind it.
    const bool widest_remembered = std::find(world.labels.begin(), world.labels.end(), widest) != world.labels.end();
    if (!world.labels.empty() && !widest_remembered) {
      if (inFront(world.labels, {widest})) {
        world.labels.clear();
        world.chosen_by = "behind";  // the widest segment below
      } else if (own.pixels[std::size_t(widest)] > config.world_outgrown_ratio * remembered_pixels &&
                 !inFront({widest}, world.labels)) {
        world.labels.clear();
        world.chosen_by = "outgrown";  // the widest segment below, named for why the memory was left
      }
    }
    if (!world.labels.empty()) world.chosen_by = "previous";
  }
  // 3. The widest segment, or the second widest when the widest is in front of it (a near thing covering most of the
  // view).
  if (world.labels.empty()) {
    int second = -1;
    for (int i = 0; i < n; ++i)
      if (i != widest && (second < 0 || own.pixels[std::size_t(i)] > own.pixels[std::size_t(second)])) second = i;
    if (world.chosen_by.empty() && second >= 0 && inFront({widest}, {second})) {
      world.labels.push_back(second);
      world.chosen_by = "behind";
    } else {
      world.labels.push_back(widest);
      if (world.chosen_by.empty()) world.chosen_by = "widest";
    }
  }

  int start = world.labels.front();
  for (const int i : world.labels)
    if (own.pixels[std::size_t(i)] > own.pixels[std::size_t(start)]) start = i;
  // 4. Pieces of the room: the segments that the world's motion explains as well as their own motions do (the merge
  // test's rule) and that are not in front of it. Without the depth order a slowly moving thing would join the world
  // and stay there (docs/decisions/0011); things that move are in front of the room.
  const bool joins_pieces = config.world_joins_pieces && depth_order && depth_order->segments == n &&
                            config.world_front_share > 0 && world.chosen_by != "prior";
  // A remembered piece is tested again: a box that the world's motion explained while it rested, or a piece whose
  // label has come to hold a moving thing, leaves the world when the test no longer holds (by its id it would
  // otherwise stay for the rest of the stream and drag the world's fit). It stays up to world_piece_keep_ratio times
  // the join's allowance, so that a room piece near the limit (blur) does not flicker in and out of the world.
  std::vector<int> remembered_pieces;
  if (joins_pieces && world.chosen_by == "previous") {
    for (const int i : world.labels)
      if (i != start) remembered_pieces.push_back(i);
    world.labels.assign(1, start);
  }
  if (joins_pieces && int(world.labels.size()) < n) {
    const std::vector<int> chosen = world.labels;
    // Candidates: not in front of the world, and not priced by their own quadratic model far beyond what the test
    // allows (a distinct motion), so that a pair of a room and people pays no pass.
    const Vector6d& world_twist = twists[std::size_t(start)];
    std::vector<int> candidates;
    auto remembered = [&](int i) {
      return std::find(remembered_pieces.begin(), remembered_pieces.end(), i) != remembered_pieces.end();
    };
    auto toleranceFactor = [&](int i) { return remembered(i) ? config.world_piece_keep_ratio : 1.0; };
    for (int i = 0; i < n; ++i) {
      if (std::find(chosen.begin(), chosen.end(), i) != chosen.end()) continue;
      if (own.pixels[std::size_t(i)] < 6.0) {  // no evidence either way: a remembered piece stays
        if (remembered(i)) world.labels.push_back(i);
        continue;
      }
      if (inFront({i}, chosen)) continue;
      const Vector6d d = world_twist - twists[std::size_t(i)];
      const double predicted = d.dot(own.curvature[std::size_t(i)] * d);
      const double allowed = std::min(config.merge_refit_tolerance * std::max(0.0, own.cost[std::size_t(i)]),
                                      config.merge_refit_noise_tolerance * noise * own.pixels[std::size_t(i)]);
      if (predicted < kRefitCandidateRatio * toleranceFactor(i) * std::max(allowed, 1e-9)) candidates.push_back(i);
    }
    const LabelCostModel under_world =
        candidates.empty()
            ? LabelCostModel()
            : labels.costModel(std::vector<Vector6d>(std::size_t(n), world_twist), use_occlusion, config);
    for (const int i : candidates) {
      if (explainedBy(under_world, i, toleranceFactor(i))) world.labels.push_back(i);
    }
  }

  // One robust rigid fit on the union, from the motion of its widest chosen member: a world split into segments gives
  // one motion, not the widest piece's.
  // With its own depth noise model (world_depth_noise_reference): the far room's depth noise is what biases a real
  // camera's odometry, while the segmentation keeps the solver's model (docs/decisions/0021).
  Config fit_config = config;
  fit_config.depth_noise_reference = config.world_depth_noise_reference;
  const std::vector<UnionFit> fit = refitUnions(labels, twists, {world.labels}, {twists[std::size_t(start)]},
                                                config.world_fit_iterations, use_occlusion, fit_config);
  world.twist = fit[0].twist;
  world.pixels = fit[0].pixels;
  world.covariance = twistCovariance(fit[0].curvature, fit[0].cost, fit[0].pixels, config);
  // What the fit cannot see (world_covariance_floor_*): on the world's motion only, so that a segment's motion relative
  // to the world (its covariance plus the world's) counts it once.
  const double t = config.world_covariance_floor_translation, r = config.world_covariance_floor_rotation;
  world.covariance.diagonal() += (Vector6d() << t * t, t * t, t * t, r * r, r * r, r * r).finished();
  for (const int i : world.labels) world.ids.push_back(segments[std::size_t(i)].id);
  world.found = true;
  return world;
}

bool StaticWorld::contains(int segment_id) const { return std::find(ids.begin(), ids.end(), segment_id) != ids.end(); }

WorldVelocity worldVelocity(const Segment& segment, const Matrix6d& segment_covariance, const StaticWorld& world,
                            bool is_world, double interval_s, const Config& config) {
  if (!(interval_s > 0))
    throw InputError("worldVelocity: the interval must be > 0 s, got " + std::to_string(interval_s));
  WorldVelocity v;
  // Relative to the world: undo the camera's motion (the world's points moved by exp(world.twist)).
  const Eigen::Matrix4d relative = se3Exp(-world.twist) * segment.transform;
  const Eigen::Vector3d c = segment.centroid;
  v.linear = (relative.topLeftCorner<3, 3>() * c + relative.topRightCorner<3, 1>() - c) / interval_s;
  v.angular = se3Log(relative).tail<3>() / interval_s;
  // First order: the two fits' covariances add; the centroid's velocity takes the rotation's part through c x.
  Matrix6d twist_cov = segment_covariance + world.covariance;
  Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
  J.topRightCorner<3, 3>() = -skew(c);  // d(v + w x c) / dw = -[c]x
  v.covariance = J * twist_cov * J.transpose() / (interval_s * interval_s);
  const double rate_deg = v.angular.norm() * 180.0 / M_PI;
  v.moving = !is_world && (v.linear.norm() > config.moving_min_speed || rate_deg > config.moving_min_rate);
  return v;
}

}  // namespace mc_flow
