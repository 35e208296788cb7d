#include "mc_flow/eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include "mc_flow/core/error.h"
#include "mc_flow/core/sampling.h"

namespace mc_flow {

namespace {

constexpr double kRadToDeg = 57.29577951308232;

template <typename A, typename B>
void requireSameSize(const char* what, const char* name_a, const Image<A>& a, const char* name_b, const Image<B>& b) {
  if (!a.sameSize(b))
    throw InputError(std::string(what) + ": " + name_a + " is " + imageSizeText(a) + " but " + name_b + " is " +
                     imageSizeText(b));
}

template <typename T>
void requireChannels(const char* what, const char* name, const Image<T>& im, int channels) {
  if (im.channels != channels)
    throw InputError(std::string(what) + ": " + name + " has " + std::to_string(im.channels) + " channels, expected " +
                     std::to_string(channels));
}

inline bool isExcluded(const ImageU8* excluded, std::size_t k) { return excluded && excluded->data[k] != 0; }

double rotationDeg(const Eigen::Matrix4d& T) {
  const double c = std::clamp((T.topLeftCorner<3, 3>().trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * kRadToDeg;
}

Eigen::Matrix4d relative(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) { return a.inverse() * b; }

// P(dof / 2, x / 2), the chi-square CDF, by the series of the regularised lower incomplete gamma function
// P(a, z) = z^a e^-z / Gamma(a + 1) * sum_n z^n / ((a + 1) ... (a + n)), in logs so that large dof do not overflow.
double chiSquareCdf(double dof, double x) {
  if (!(x > 0)) return 0.0;
  const double a = 0.5 * dof, z = 0.5 * x;
  double term = 1.0, sum = 1.0;
  for (int n = 1; n < 1000000; ++n) {
    term *= z / (a + n);
    sum += term;
    if (!std::isfinite(sum)) return 1.0;  // z far above a: the CDF is 1 to double precision
    if (term < sum * 1e-16) break;
  }
  return std::min(1.0, std::exp(a * std::log(z) - z - std::lgamma(a + 1.0) + std::log(sum)));
}

}  // namespace

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const auto middle = values.begin() + std::ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

double percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  const std::size_t rank = std::size_t(std::ceil(q * double(values.size())));
  const auto at = values.begin() + std::ptrdiff_t(std::clamp<std::size_t>(rank, 1, values.size()) - 1);
  std::nth_element(values.begin(), at, values.end());
  return *at;
}

FlowErrors opticalFlowErrors(const ImageF& estimate, const ImageF& truth, const ImageU8* excluded) {
  requireChannels("opticalFlowErrors", "estimate", estimate, 2);
  requireChannels("opticalFlowErrors", "truth", truth, 2);
  requireSameSize("opticalFlowErrors", "estimate", estimate, "truth", truth);
  if (excluded) requireSameSize("opticalFlowErrors", "estimate", estimate, "excluded mask", *excluded);

  FlowErrors errors;
  double sum_epe = 0, sum_aae = 0;
  const std::size_t n = estimate.pixelCount();
  for (std::size_t k = 0; k < n; ++k) {
    if (isExcluded(excluded, k)) continue;
    const double u = estimate.data[2 * k], v = estimate.data[2 * k + 1];
    const double ug = truth.data[2 * k], vg = truth.data[2 * k + 1];
    if (!(std::isfinite(u) && std::isfinite(v) && std::isfinite(ug) && std::isfinite(vg))) continue;
    sum_epe += std::hypot(u - ug, v - vg);
    // Barron et al.: angle between the space-time vectors (u, v, 1) and (u_gt, v_gt, 1).
    const double cosine = (u * ug + v * vg + 1.0) / std::sqrt((u * u + v * v + 1.0) * (ug * ug + vg * vg + 1.0));
    sum_aae += std::acos(std::clamp(cosine, -1.0, 1.0)) * kRadToDeg;
    ++errors.pixels;
  }
  if (errors.pixels > 0) {
    errors.epe = sum_epe / double(errors.pixels);
    errors.aae_deg = sum_aae / double(errors.pixels);
  }
  return errors;
}

double sceneFlowEpe(const ImageF& estimate, const ImageF& truth, const ImageU8* excluded, std::size_t* pixels) {
  requireChannels("sceneFlowEpe", "estimate", estimate, 3);
  requireChannels("sceneFlowEpe", "truth", truth, 3);
  requireSameSize("sceneFlowEpe", "estimate", estimate, "truth", truth);
  if (excluded) requireSameSize("sceneFlowEpe", "estimate", estimate, "excluded mask", *excluded);

  double sum = 0;
  std::size_t used = 0;
  const std::size_t n = estimate.pixelCount();
  for (std::size_t k = 0; k < n; ++k) {
    if (isExcluded(excluded, k)) continue;
    const float* e = &estimate.data[3 * k];
    const float* t = &truth.data[3 * k];
    bool finite = true;
    for (int c = 0; c < 3; ++c) finite = finite && std::isfinite(e[c]) && std::isfinite(t[c]);
    if (!finite) continue;
    const double dx = double(e[0]) - t[0], dy = double(e[1]) - t[1], dz = double(e[2]) - t[2];
    sum += std::sqrt(dx * dx + dy * dy + dz * dz);
    ++used;
  }
  if (pixels) *pixels = used;
  return used > 0 ? sum / double(used) : 0.0;
}

ResidualRmse warpResidualRmse(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K,
                              const ImageF* scene_flow, const ImageU8* excluded) {
  requireSameSize("warpResidualRmse", "frame1 depth", frame1.depth, "frame1 intensity", frame1.intensity);
  requireSameSize("warpResidualRmse", "frame2 depth", frame2.depth, "frame2 intensity", frame2.intensity);
  if (scene_flow) {
    requireChannels("warpResidualRmse", "scene flow", *scene_flow, 3);
    requireSameSize("warpResidualRmse", "scene flow", *scene_flow, "frame1 depth", frame1.depth);
  }
  if (excluded) requireSameSize("warpResidualRmse", "excluded mask", *excluded, "frame1 depth", frame1.depth);

  const int w = frame1.depth.width, h = frame1.depth.height;
  double sum_photo = 0, sum_geo = 0;
  std::size_t used = 0;
#pragma omp parallel for schedule(static) reduction(+ : sum_photo, sum_geo, used)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t k = std::size_t(y) * w + x;
      const float z = frame1.depth.data[k];
      if (!isValidDepth(z) || isExcluded(excluded, k)) continue;
      double P2[3] = {z * (x - K.cx) / K.fx, z * (y - K.cy) / K.fy, z};
      if (scene_flow) {
        const float* f = &scene_flow->data[3 * k];
        if (!(std::isfinite(f[0]) && std::isfinite(f[1]) && std::isfinite(f[2]))) continue;
        for (int c = 0; c < 3; ++c) P2[c] += f[c];
      }
      if (!(P2[2] > 0)) continue;
      const float u = float(K.fx * P2[0] / P2[2] + K.cx), v = float(K.fy * P2[1] / P2[2] + K.cy);
      float i2 = 0, z2 = 0;
      if (!sampleBilinear(frame2.intensity, u, v, 0, i2) || !sampleDepthBilinear(frame2.depth, u, v, z2)) continue;
      const double photometric = double(frame1.intensity.data[k]) - i2;
      const double geometric = P2[2] - z2;
      sum_photo += photometric * photometric;
      sum_geo += geometric * geometric;
      ++used;
    }

  ResidualRmse rmse;
  rmse.pixels = used;
  if (used > 0) {
    rmse.photometric = std::sqrt(sum_photo / double(used));
    rmse.geometric = std::sqrt(sum_geo / double(used));
  }
  return rmse;
}

double segmentationAgreement(const ImageI32& estimate, const ImageI32& truth) {
  requireSameSize("segmentationAgreement", "estimate", estimate, "truth", truth);
  std::unordered_map<std::uint64_t, std::size_t> overlap;
  std::size_t total = 0;
  const std::size_t n = estimate.pixelCount();
  for (std::size_t k = 0; k < n; ++k) {
    const std::int32_t e = estimate.data[k], t = truth.data[k];
    if (e < 0 || t < 0) continue;
    ++overlap[(std::uint64_t(std::uint32_t(e)) << 32) | std::uint32_t(t)];
    ++total;
  }
  if (total == 0) return 0.0;

  // Greedy one-to-one matching: largest overlaps first (ties broken by ids so the result is deterministic).
  std::vector<std::tuple<std::size_t, std::int32_t, std::int32_t>> pairs;
  pairs.reserve(overlap.size());
  for (const auto& [key, count] : overlap)
    pairs.emplace_back(count, std::int32_t(key >> 32), std::int32_t(key & 0xffffffffu));
  std::sort(pairs.begin(), pairs.end(), [](const auto& a, const auto& b) {
    if (std::get<0>(a) != std::get<0>(b)) return std::get<0>(a) > std::get<0>(b);
    if (std::get<1>(a) != std::get<1>(b)) return std::get<1>(a) < std::get<1>(b);
    return std::get<2>(a) < std::get<2>(b);
  });
  std::unordered_map<std::int32_t, bool> estimate_used, truth_used;
  std::size_t matched = 0;
  for (const auto& [count, e, t] : pairs) {
    if (estimate_used[e] || truth_used[t]) continue;
    estimate_used[e] = truth_used[t] = true;
    matched += count;
  }
  return double(matched) / double(total);
}

namespace {
// Calls visit(in_a, in_b) for every pixel of two masks of one size that `valid` (null: every pixel) keeps.
template <typename Visit>
void visitMasks(const char* name, const ImageU8& a, const ImageU8& b, const ImageU8* valid, Visit visit) {
  requireSameSize(name, "a", a, "b", b);
  if (valid) requireSameSize(name, "a", a, "valid mask", *valid);
  const std::size_t n = a.pixelCount();
  for (std::size_t k = 0; k < n; ++k)
    if (!valid || valid->data[k] != 0) visit(a.data[k] != 0, b.data[k] != 0);
}
}  // namespace

double maskAgreement(const ImageU8& a, const ImageU8& b, const ImageU8* valid) {
  std::size_t agree = 0, total = 0;
  visitMasks("maskAgreement", a, b, valid, [&](bool in_a, bool in_b) {
    ++total;
    agree += in_a == in_b ? 1 : 0;
  });
  return total > 0 ? double(agree) / double(total) : 0.0;
}

double maskIou(const ImageU8& a, const ImageU8& b, const ImageU8* valid) {
  std::size_t both = 0, either = 0;
  visitMasks("maskIou", a, b, valid, [&](bool in_a, bool in_b) {
    both += in_a && in_b;
    either += in_a || in_b;
  });
  return either > 0 ? double(both) / double(either) : 1.0;
}

RegionOverlap regionOverlap(const ImageI32& labels, const std::vector<int>& ids, const ImageI32& truth, int truth_id,
                            const ImageU8* valid) {
  requireSameSize("regionOverlap", "labels", labels, "truth", truth);
  if (valid) requireSameSize("regionOverlap", "labels", labels, "valid mask", *valid);
  RegionOverlap o;
  const std::size_t n = labels.pixelCount();
  for (std::size_t k = 0; k < n; ++k) {
    if (valid && valid->data[k] == 0) continue;
    const bool in_estimate = std::find(ids.begin(), ids.end(), labels.data[k]) != ids.end();
    const bool in_truth = truth.data[k] == truth_id;
    o.estimate += in_estimate;
    o.truth += in_truth;
    o.common += in_estimate && in_truth;
  }
  return o;
}

double nees(const Vector6d& error, const Matrix6d& covariance) { return error.dot(covariance.ldlt().solve(error)); }

double chiSquareQuantile(double dof, double probability) {
  if (!(dof > 0) || !(probability > 0 && probability < 1))
    throw InputError("chiSquareQuantile: needs dof > 0 and 0 < probability < 1, got dof " + std::to_string(dof) +
                     ", probability " + std::to_string(probability));
  // The CDF rises monotonically; the quantile lies below dof + 40 sqrt(2 dof) + 100 for every probability a double
  // distinguishes from 1.
  double lo = 0, hi = dof + 40.0 * std::sqrt(2.0 * dof) + 100.0;
  while (hi - lo > 1e-10 * hi) {
    const double mid = 0.5 * (lo + hi);
    (chiSquareCdf(dof, mid) < probability ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

namespace {

void requireMaxDifference(double max_difference) {
  if (!(max_difference >= 0)) throw InputError("max difference must be >= 0 s, got " + std::to_string(max_difference));
}

StampedPoses sortedByStamp(const StampedPoses& poses) {
  StampedPoses sorted = poses;
  std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return sorted;
}

// The pose of `sorted` (by stamp) nearest to stamp t, or null when none lies within max_difference.
const Eigen::Matrix4d* nearestPose(const StampedPoses& sorted, double t, double max_difference) {
  auto it = std::lower_bound(sorted.begin(), sorted.end(), t, [](const auto& a, double v) { return a.first < v; });
  const auto* best = it != sorted.end() ? &*it : nullptr;
  if (it != sorted.begin() && (!best || t - std::prev(it)->first < best->first - t)) best = &*std::prev(it);
  if (!best || std::fabs(best->first - t) > max_difference) return nullptr;
  return &best->second;
}

}  // namespace

TrajectoryErrors evaluateTrajectory(const StampedPoses& ground_truth, const StampedPoses& estimate,
                                    double max_difference, double time_offset) {
  requireMaxDifference(max_difference);
  const StampedPoses gt = sortedByStamp(ground_truth);
  std::vector<std::pair<Eigen::Matrix4d, Eigen::Matrix4d>> matched;  // (ground truth, estimate)
  std::vector<double> stamps;
  StampedPoses est = estimate;  // in time order: the RPE pairs consecutive and one-second-apart poses
  std::stable_sort(est.begin(), est.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [stamp, pose] : est) {
    const Eigen::Matrix4d* truth = nearestPose(gt, stamp + time_offset, max_difference);
    if (!truth) continue;
    matched.emplace_back(*truth, pose);
    stamps.push_back(stamp);
  }
  if (matched.size() < 3)
    throw InputError("trajectory evaluation: " + std::to_string(matched.size()) + " of " +
                     std::to_string(estimate.size()) + " estimated poses have a ground-truth pose within " +
                     std::to_string(max_difference) + " s (" + std::to_string(ground_truth.size()) +
                     " ground-truth poses); at least 3 are needed");
  TrajectoryErrors e;
  e.matched = int(matched.size());
  Eigen::Matrix3Xd from(3, e.matched), to(3, e.matched);
  for (int i = 0; i < e.matched; ++i) {
    from.col(i) = matched[std::size_t(i)].second.topRightCorner<3, 1>();
    to.col(i) = matched[std::size_t(i)].first.topRightCorner<3, 1>();
  }
  e.alignment = Eigen::umeyama(from, to, false);
  double sum = 0;
  for (int i = 0; i < e.matched; ++i) {
    const Eigen::Vector3d aligned = (e.alignment * from.col(i).homogeneous()).head<3>();
    sum += (aligned - to.col(i)).squaredNorm();
    e.positions.emplace_back(to.col(i), aligned);
  }
  e.ate_rmse_m = std::sqrt(sum / e.matched);
  // RPE over consecutive matched frames, and over about one second.
  double t_sum = 0, r_sum = 0, t_sum_s = 0, r_sum_s = 0;
  auto add = [&](std::size_t i, std::size_t j, double& ts, double& rs, int& count) {
    const Eigen::Matrix4d error =
        relative(relative(matched[i].first, matched[j].first), relative(matched[i].second, matched[j].second));
    ts += error.topRightCorner<3, 1>().squaredNorm();
    const double r = rotationDeg(error);
    rs += r * r;
    ++count;
  };
  for (std::size_t i = 0; i + 1 < matched.size(); ++i) add(i, i + 1, t_sum, r_sum, e.rpe_frame_pairs);
  for (std::size_t i = 0; i < matched.size(); ++i) {
    const auto j = std::lower_bound(stamps.begin() + long(i), stamps.end(), stamps[i] + 1.0);
    if (j == stamps.end()) break;
    add(i, std::size_t(j - stamps.begin()), t_sum_s, r_sum_s, e.rpe_second_pairs);
  }
  e.rpe_frame_trans_m = std::sqrt(t_sum / std::max(1, e.rpe_frame_pairs));
  e.rpe_frame_rot_deg = std::sqrt(r_sum / std::max(1, e.rpe_frame_pairs));
  if (e.rpe_second_pairs > 0) {
    e.rpe_second_trans_m = std::sqrt(t_sum_s / e.rpe_second_pairs);
    e.rpe_second_rot_deg = std::sqrt(r_sum_s / e.rpe_second_pairs);
  }
  return e;
}

OdometryConsistency odometryConsistency(const StampedPoses& ground_truth, const std::vector<OdometryStep>& steps,
                                        double max_difference, double time_offset) {
  requireMaxDifference(max_difference);
  const StampedPoses gt = sortedByStamp(ground_truth);
  std::vector<double> values;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const OdometryStep& step = steps[i];
    const Eigen::Matrix4d* g1 = nearestPose(gt, step.first + time_offset, max_difference);
    const Eigen::Matrix4d* g2 = nearestPose(gt, step.second + time_offset, max_difference);
    if (!g1 || !g2) continue;
    const Eigen::LLT<Matrix6d> llt(step.covariance);
    if (llt.info() != Eigen::Success || !step.covariance.isApprox(step.covariance.transpose(), 1e-9) ||
        !step.covariance.allFinite())
      throw InputError("odometry consistency: step " + std::to_string(i) + " (stamps " + std::to_string(step.first) +
                       ", " + std::to_string(step.second) +
                       ") has a covariance that is not symmetric positive definite");
    values.push_back(nees(step.twist - se3Log(Eigen::Matrix4d(g1->inverse() * *g2)), step.covariance));
  }
  if (values.empty())
    throw InputError("odometry consistency: none of " + std::to_string(steps.size()) +
                     " steps has ground-truth poses within " + std::to_string(max_difference) + " s of both stamps (" +
                     std::to_string(ground_truth.size()) + " ground-truth poses)");
  OdometryConsistency c;
  c.matched = int(values.size());
  double sum = 0;
  int inside = 0;
  const double low = chiSquareQuantile(6, 0.025), high = chiSquareQuantile(6, 0.975);
  for (const double v : values) {
    sum += v;
    inside += v >= low && v <= high ? 1 : 0;
  }
  c.nees_mean = sum / c.matched;
  c.inside95 = double(inside) / c.matched;
  c.nees_median = median(values);
  // The sum of N consistent NEES values is chi-square with 6 N degrees of freedom.
  c.mean_low = chiSquareQuantile(6.0 * c.matched, 0.025) / c.matched;
  c.mean_high = chiSquareQuantile(6.0 * c.matched, 0.975) / c.matched;
  return c;
}

}  // namespace mc_flow
