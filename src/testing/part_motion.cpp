#include "mc_flow/testing/part_motion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

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
    LabelMoments moments;  // the part's frame-1 points, for its longest axis
    double epe_sum = 0;
    int epe_pixels = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (pair.gt_parts(x, y) != part.id) continue;
        if (std::isfinite(points(x, y, 2))) moments.add(Eigen::Vector3d(points(x, y, 0), points(x, y, 1), points(x, y, 2)));
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

bool armLinksApart(const std::vector<PartMotionError>& parts) {
  int upper = 0, fore = 0;
  for (const PartMotionError& p : parts) {
    if (p.name == "upper_arm") upper = p.segment;
    if (p.name == "forearm") fore = p.segment;
  }
  return upper > 0 && fore > 0 && upper != fore;
}

}  // namespace mc_flow
