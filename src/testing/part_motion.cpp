#include "mc_flow/testing/part_motion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <vector>

#include <Eigen/Geometry>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_adaptation.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/se3.h"

namespace mc_flow {
namespace {

double rotationAngleDeg(const Eigen::Matrix4d& T) {
  return Eigen::AngleAxisd(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).angle() * 180.0 / M_PI;
}

}  // namespace

std::vector<PartMotionError> partMotionErrors(const Result& result, const SyntheticPair& pair) {
  const int w = pair.gt_parts.width, h = pair.gt_parts.height;
  if (result.labels.width != w || result.labels.height != h || result.optical_flow.width != w ||
      result.optical_flow.height != h)
    throw InputError("partMotionErrors: result of " + std::to_string(result.labels.width) + "x" +
                     std::to_string(result.labels.height) + " for a scene of " + std::to_string(w) + "x" +
                     std::to_string(h));
  const ImageF points = backProject(pair.frame1.depth, pair.intrinsics);
  std::vector<PartMotionError> out;
  for (const SyntheticPart& part : pair.parts) {
    PartMotionError e;
    e.part_id = part.id;
    e.name = part.name;
    e.true_rotation_deg = rotationAngleDeg(se3Exp(part.twist));
    std::map<int, int> votes;
    LabelMoments moments;                   // the part's frame-1 points, for its longest axis
    std::vector<Eigen::Vector3d> from, to;  // the part's points and where its true scene flow takes them
    double epe_sum = 0;
    int epe_pixels = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (pair.gt_parts(x, y) != part.id) continue;
        if (std::isfinite(points(x, y, 2))) {
          const Eigen::Vector3d P(points(x, y, 0), points(x, y, 1), points(x, y, 2));
          moments.add(P);
          const Eigen::Vector3d flow(pair.gt_scene_flow(x, y, 0), pair.gt_scene_flow(x, y, 1),
                                     pair.gt_scene_flow(x, y, 2));
          if (flow.allFinite()) {
            from.push_back(P);
            to.push_back(P + flow);
          }
        }
        const int segment = result.labels(x, y);
        if (segment > 0) {
          ++votes[segment];
          ++e.pixels;
        }
        const float u = result.optical_flow(x, y, 0), v = result.optical_flow(x, y, 1);
        const float gu = pair.gt_optical_flow(x, y, 0), gv = pair.gt_optical_flow(x, y, 1);
        if (pair.gt_occlusion(x, y) || !std::isfinite(u) || !std::isfinite(v) || !std::isfinite(gu) ||
            !std::isfinite(gv))
          continue;
        epe_sum += std::hypot(double(u - gu), double(v - gv));
        ++epe_pixels;
      }
    e.flow_epe_px = epe_pixels > 0 ? epe_sum / epe_pixels : std::numeric_limits<double>::quiet_NaN();
    e.rigid_fit_error_deg = std::numeric_limits<double>::quiet_NaN();
    if (from.size() >= 3) {
      Eigen::Matrix3Xd src(3, Eigen::Index(from.size())), dst(3, Eigen::Index(to.size()));
      for (std::size_t k = 0; k < from.size(); ++k) {
        src.col(Eigen::Index(k)) = from[k];
        dst.col(Eigen::Index(k)) = to[k];
      }
      const Eigen::Matrix4d fit = Eigen::umeyama(src, dst, false);
      e.rigid_fit_error_deg = rotationAngleDeg(fit.inverse() * se3Exp(part.twist));
    }
    e.rotation_error_deg = e.rotation_error_along_deg = e.rotation_error_across_deg =
        std::numeric_limits<double>::quiet_NaN();
    int best_votes = 0;
    for (const auto& [segment, count] : votes)
      if (count > best_votes) {
        best_votes = count;
        e.segment = segment;
      }
    for (const Segment& s : result.segments)
      if (e.segment > 0 && s.id == e.segment) {
        e.covered_fraction = double(best_votes) / double(e.pixels);
        const Eigen::Matrix4d D = se3Exp(s.twist).inverse() * se3Exp(part.twist);
        e.rotation_error_deg = rotationAngleDeg(D);
        const Eigen::AngleAxisd error(Eigen::Matrix3d(D.topLeftCorner<3, 3>()));
        const Eigen::Vector3d error_vector = error.angle() * error.axis() * 180.0 / M_PI;
        if (moments.count >= 3) {
          const double along = error_vector.dot(moments.principalAxis());
          e.rotation_error_along_deg = std::abs(along);
          e.rotation_error_across_deg = std::sqrt(std::max(0.0, error_vector.squaredNorm() - along * along));
        }
      }
    out.push_back(e);
  }
  return out;
}

Result truthSegmentation(const SyntheticPair& pair) {
  Result r;
  r.width = pair.gt_parts.width;
  r.height = pair.gt_parts.height;
  r.intrinsics = pair.intrinsics;
  r.labels = ImageI32(r.width, r.height, 1, 0);
  r.optical_flow = ImageF(r.width, r.height, 2, 0.f);
  r.scene_flow = ImageF(r.width, r.height, 3, 0.f);
  r.moved_depth = pair.frame1.depth;
  for (std::size_t k = 0; k < pair.parts.size(); ++k) {
    Segment s;
    s.id = int(k) + 1;
    r.segments.push_back(s);
  }
  for (int y = 0; y < r.height; ++y)
    for (int x = 0; x < r.width; ++x) {
      if (!(pair.frame1.depth(x, y) > 0)) continue;  // gt_parts says 0 (the background) where there is no surface
      for (std::size_t k = 0; k < pair.parts.size(); ++k)
        if (pair.gt_parts(x, y) == pair.parts[k].id) r.labels(x, y) = int(k) + 1;
    }
  r.next_id = int(pair.parts.size()) + 1;
  return r;
}

bool armLinksApart(const std::vector<PartMotionError>& parts) {
  int upper = 0, fore = 0;
  for (const PartMotionError& p : parts) {
    if (p.name == "upper_arm") upper = p.segment;
    if (p.name == "forearm") fore = p.segment;
  }
  return upper > 0 && fore > 0 && upper != fore;
}

}  // namespace mc_flow
