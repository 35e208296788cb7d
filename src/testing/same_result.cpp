#include "mc_flow/testing/same_result.h"

#include <cstring>
#include <vector>

namespace mc_flow {

namespace {

template <typename T>
bool sameBytes(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

template <typename Derived>
bool sameBytes(const Eigen::MatrixBase<Derived>& a, const Eigen::MatrixBase<Derived>& b) {
  const typename Derived::PlainObject pa = a, pb = b;
  return std::memcmp(pa.data(), pb.data(), sizeof(typename Derived::Scalar) * std::size_t(pa.size())) == 0;
}

}  // namespace

std::string firstDifference(const Result& a, const Result& b) {
  if (a.scene_flow.width != b.scene_flow.width || a.scene_flow.height != b.scene_flow.height) return "size";
  if (a.soft_labels.count != b.soft_labels.count) return "label count";
  if (!sameBytes(a.labels.data, b.labels.data)) return "labels";
  if (!sameBytes(a.soft_labels.data, b.soft_labels.data)) return "soft labels";
  if (!sameBytes(a.scene_flow.data, b.scene_flow.data)) return "scene flow";
  if (!sameBytes(a.optical_flow.data, b.optical_flow.data)) return "optical flow";
  if (!sameBytes(a.moved_depth.data, b.moved_depth.data)) return "moved depth";
  if (!sameBytes(a.occlusion.data, b.occlusion.data)) return "occlusion";
  if (a.segments.size() != b.segments.size())
    return "segment count (" + std::to_string(a.segments.size()) + " against " + std::to_string(b.segments.size()) +
           ")";
  for (std::size_t k = 0; k < a.segments.size(); ++k) {
    const Segment &sa = a.segments[k], &sb = b.segments[k];
    const std::string which = "segment " + std::to_string(k) + "'s ";
    if (sa.id != sb.id) return which + "id";
    if (!sameBytes(sa.twist, sb.twist)) return which + "twist";
    if (!sameBytes(sa.transform, sb.transform)) return which + "transform";
    if (std::memcmp(&sa.support, &sb.support, sizeof(double)) != 0) return which + "support";
    if (!sameBytes(sa.covariance, sb.covariance)) return which + "covariance";
  }
  if (!sameBytes(a.world.twist, b.world.twist)) return "the static world's twist";
  return "";
}

}  // namespace mc_flow
