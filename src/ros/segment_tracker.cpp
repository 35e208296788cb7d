#include "mc_flow/ros/segment_tracker.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

namespace mc_flow_ros {

namespace {

Rgb8 hsvToRgb(double hue, double saturation, double value) {
  const double h = std::fmod(hue, 1.0) * 6.0;
  const int sector = int(h) % 6;
  const double f = h - std::floor(h);
  const double p = value * (1 - saturation), q = value * (1 - saturation * f), t = value * (1 - saturation * (1 - f));
  double r = 0, g = 0, b = 0;
  switch (sector) {
    case 0: r = value; g = t; b = p; break;
    case 1: r = q; g = value; b = p; break;
    case 2: r = p; g = value; b = t; break;
    case 3: r = p; g = q; b = value; break;
    case 4: r = t; g = p; b = value; break;
    default: r = value; g = p; b = q; break;
  }
  auto to8 = [](double v) { return std::uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); };
  return {to8(r), to8(g), to8(b)};
}

}  // namespace

Rgb8 colourForId(std::uint32_t id) {
  if (id == 0) return {60, 60, 60};
  // Golden-ratio hue steps keep consecutive ids far apart on the colour wheel; two brightness levels
  // separate ids whose hues end up close.
  const double golden = 0.6180339887498949;
  const double hue = std::fmod(0.11 + golden * id, 1.0);
  const double value = (id % 2 == 0) ? 0.80 : 0.98;
  const double saturation = (id % 3 == 0) ? 0.60 : 0.85;
  return hsvToRgb(hue, saturation, value);
}

SegmentTracker::SegmentTracker(const Options& options) : options_(options) {}

void SegmentTracker::reset() { predicted_ids_ = mc_flow::ImageI32(); }

std::vector<std::uint32_t> SegmentTracker::update(const mc_flow::ImageI32& labels, int segment_count,
                                                  const mc_flow::ImageF& optical_flow) {
  const int m = std::max(segment_count, 0);
  std::vector<std::uint32_t> ids(std::size_t(m), 0);
  const bool have_previous = !predicted_ids_.empty() && predicted_ids_.sameSize(labels);

  if (have_previous) {
    // Overlap counts between old ids (moved onto these pixels) and new labels, and the region sizes.
    std::map<std::pair<std::uint32_t, int>, long> overlap;
    std::map<std::uint32_t, long> old_size;
    std::vector<long> new_size(std::size_t(m) + 1, 0);
    for (std::size_t i = 0; i < labels.pixelCount(); ++i) {
      const int label = labels.data[i];
      const auto old_id = std::uint32_t(std::max(predicted_ids_.data[i], 0));
      if (label > 0 && label <= m) ++new_size[std::size_t(label)];
      if (old_id > 0) ++old_size[old_id];
      if (label > 0 && label <= m && old_id > 0) ++overlap[{old_id, label}];
    }
    std::vector<std::tuple<long, std::uint32_t, int>> candidates;
    for (const auto& [key, count] : overlap) candidates.emplace_back(count, key.first, key.second);
    // Largest overlap first; ties broken by id and label so the result is deterministic.
    std::sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
      if (std::get<0>(a) != std::get<0>(b)) return std::get<0>(a) > std::get<0>(b);
      if (std::get<1>(a) != std::get<1>(b)) return std::get<1>(a) < std::get<1>(b);
      return std::get<2>(a) < std::get<2>(b);
    });
    std::map<std::uint32_t, bool> id_taken;
    for (const auto& [count, old_id, label] : candidates) {
      if (ids[std::size_t(label - 1)] != 0 || id_taken[old_id]) continue;
      const long smaller = std::min(old_size[old_id], new_size[std::size_t(label)]);
      if (smaller <= 0 || double(count) < options_.min_overlap * double(smaller)) continue;
      ids[std::size_t(label - 1)] = old_id;
      id_taken[old_id] = true;
    }
  }
  for (auto& id : ids) {
    if (id == 0) id = next_id_++;
  }

  // Move this pair's ids onto the next pair's pixels (forward warp by the optical flow; holes stay 0).
  predicted_ids_ = mc_flow::ImageI32(labels.width, labels.height, 1, 0);
  const bool have_flow = optical_flow.sameSize(labels) && optical_flow.channels >= 2;
  for (int y = 0; y < labels.height; ++y) {
    for (int x = 0; x < labels.width; ++x) {
      const int label = labels(x, y);
      if (label <= 0 || label > m) continue;
      double tx = x, ty = y;
      if (have_flow) {
        const float u = optical_flow(x, y, 0), v = optical_flow(x, y, 1);
        if (!std::isfinite(u) || !std::isfinite(v)) continue;
        tx += u;
        ty += v;
      }
      const long ix = std::lround(tx), iy = std::lround(ty);
      if (ix < 0 || iy < 0 || ix >= labels.width || iy >= labels.height) continue;
      predicted_ids_(int(ix), int(iy)) = std::int32_t(ids[std::size_t(label - 1)]);
    }
  }
  return ids;
}

}  // namespace mc_flow_ros
