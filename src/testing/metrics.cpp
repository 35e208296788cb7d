#include "mc_flow/testing/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <unordered_map>
#include <vector>

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

}  // namespace

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
  for (const auto& [key, count] : overlap) pairs.emplace_back(count, std::int32_t(key >> 32), std::int32_t(key & 0xffffffffu));
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

double maskAgreement(const ImageU8& a, const ImageU8& b, const ImageU8* valid) {
  requireSameSize("maskAgreement", "a", a, "b", b);
  if (valid) requireSameSize("maskAgreement", "a", a, "valid mask", *valid);
  std::size_t agree = 0, total = 0;
  const std::size_t n = a.pixelCount();
  for (std::size_t k = 0; k < n; ++k) {
    if (valid && valid->data[k] == 0) continue;
    ++total;
    agree += (a.data[k] != 0) == (b.data[k] != 0) ? 1 : 0;
  }
  return total > 0 ? double(agree) / double(total) : 0.0;
}

}  // namespace mc_flow
