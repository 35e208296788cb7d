// Stream mode: the previous pair's segments moved into the next frame 1 (forward splatting of the labelled
// points by their scene flow, with a depth test), resampled to a pyramid level, or matched to a cold
// solve's segments by overlap.
#include "mc_flow/core/warm_start.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>

#include "mc_flow/core/error.h"
#include "mc_flow/core/solver.h"

namespace mc_flow {

ImageI32 carrySegmentIds(const Result& previous, const ImageF& points, double depth_tolerance) {
  return carryIds(previous.labels, previous, points, depth_tolerance);
}

ImageI32 carryIds(const ImageI32& ids, const Result& previous, const ImageF& points, double depth_tolerance) {
  const int W = points.width, H = points.height;
  if (previous.width != W || previous.height != H)
    throw InputError("warm start: the previous result is " + std::to_string(previous.width) + "x" +
                     std::to_string(previous.height) + " but the frame is " + std::to_string(W) + "x" +
                     std::to_string(H));
  if (ids.data.size() != std::size_t(W) * H || previous.scene_flow.data.size() != std::size_t(W) * H * 3 ||
      previous.optical_flow.data.size() != std::size_t(W) * H * 2 ||
      previous.moved_depth.data.size() != std::size_t(W) * H)
    throw InputError("warm start: the previous result has no labels or flow at its " + std::to_string(W) + "x" +
                     std::to_string(H) + " resolution");
  // Forward splat with a depth buffer: the nearest moved point wins a pixel.
  ImageF nearest(W, H, 1, std::numeric_limits<float>::infinity());
  ImageI32 splat(W, H, 1, 0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const int id = ids(x, y);
      if (id <= 0) continue;
      const float u = float(x) + previous.optical_flow(x, y, 0), v = float(y) + previous.optical_flow(x, y, 1);
      if (!std::isfinite(u) || !std::isfinite(v)) continue;
      const int tx = int(std::lround(u)), ty = int(std::lround(v));
      if (tx < 0 || ty < 0 || tx >= W || ty >= H) continue;
      const float z_moved = previous.moved_depth(x, y);  // where the point is in frame 2, seen from frame 2's camera
      if (!(z_moved > 0) || z_moved >= nearest(tx, ty)) continue;
      nearest(tx, ty) = z_moved;
      splat(tx, ty) = id;
    }
  ImageI32 carried(W, H, 1, 0);
  auto observed = [&](int x, int y) { return points(x, y, 2); };
  // The splat above stays serial (the nearest point wins a pixel); the passes below write one pixel each.
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      if (splat(x, y) > 0 && std::isfinite(observed(x, y)) &&
          std::abs(nearest(x, y) - observed(x, y)) <= depth_tolerance)
        carried(x, y) = splat(x, y);
  // Close the one-pixel gaps that rounding leaves where a surface comes closer (it covers more pixels):
  // a pixel without an id takes the most common id of its 8 neighbours whose observed depth is close.
  ImageI32 closed = carried;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (carried(x, y) > 0 || !std::isfinite(observed(x, y))) continue;
      int best_id = 0, best_count = 0;
      int ids[8], counts[8], n = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= W || ny >= H) continue;
          const int id = carried(nx, ny);
          if (id <= 0 || !(std::abs(observed(nx, ny) - observed(x, y)) <= depth_tolerance)) continue;
          int k = 0;
          while (k < n && ids[k] != id) ++k;
          if (k == n) {
            ids[n] = id;
            counts[n++] = 0;
          }
          if (++counts[k] > best_count) {
            best_count = counts[k];
            best_id = id;
          }
        }
      if (best_count >= 2) closed(x, y) = best_id;
    }
  return closed;
}

CarriedLabels carriedLabelsAtLevel(const ImageI32& carried_ids, const ImageF& level_points, int scale) {
  if (scale < 1 || (scale & (scale - 1)) != 0)
    throw InputError("carried labels: scale " + std::to_string(scale) + " is not a power of two");
  const int w = level_points.width, h = level_points.height;
  if (carried_ids.width < w * scale || carried_ids.height < h * scale)
    throw InputError("carried labels: a " + std::to_string(carried_ids.width) + "x" +
                     std::to_string(carried_ids.height) + " id image cannot cover a " + std::to_string(w) + "x" +
                     std::to_string(h) + " level at scale " + std::to_string(scale));
  CarriedLabels out;
  out.hard = ImageI32(w, h, 1, -1);
  // Each level pixel's majority id (0: none, -1: no depth), in parallel; then the label indices in raster order, so
  // that they do not depend on the threads.
  ImageI32 majority(w, h, 1, 0);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y) {
    std::vector<std::pair<int, int>> counts;  // (id, count) within a block
    for (int x = 0; x < w; ++x) {
      if (!std::isfinite(level_points(x, y, 2))) {
        majority(x, y) = -1;
        continue;
      }
      counts.clear();
      for (int by = 0; by < scale; ++by)
        for (int bx = 0; bx < scale; ++bx) {
          const int id = carried_ids(x * scale + bx, y * scale + by);
          if (id <= 0) continue;
          auto it = std::find_if(counts.begin(), counts.end(), [id](const auto& c) { return c.first == id; });
          if (it == counts.end())
            counts.emplace_back(id, 1);
          else
            ++it->second;
        }
      if (counts.empty()) continue;
      // The most common id; ties go to the smaller id, so the result does not depend on the visiting order.
      const auto best = std::max_element(counts.begin(), counts.end(), [](const auto& a, const auto& b) {
        return a.second < b.second || (a.second == b.second && a.first > b.first);
      });
      if (2 * best->second >= scale * scale) majority(x, y) = best->first;
    }
  }
  std::map<int, int> index_of_id;
  for (std::size_t k = 0; k < majority.data.size(); ++k) {
    const int id = majority.data[k];
    if (id < 0) continue;
    ++out.valid;
    if (id == 0) continue;
    auto [it, inserted] = index_of_id.emplace(id, int(index_of_id.size()));
    if (inserted) out.ids.push_back(id);
    out.hard.data[k] = it->second;
    ++out.covered;
  }
  return out;
}

std::vector<int> matchSegmentIds(const ImageI32& labels, int segment_count, const ImageI32& carried_ids,
                                 double min_overlap, int& next_id) {
  if (labels.width != carried_ids.width || labels.height != carried_ids.height)
    throw InputError("segment ids: labels are " + std::to_string(labels.width) + "x" + std::to_string(labels.height) +
                     ", carried ids " + std::to_string(carried_ids.width) + "x" + std::to_string(carried_ids.height));
  std::vector<double> size(std::size_t(segment_count) + 1, 0.0);
  std::map<int, double> carried_size;
  std::map<std::pair<int, int>, double> overlap;  // (segment, id) -> pixels
  for (std::size_t k = 0; k < labels.data.size(); ++k) {
    const int s = labels.data[k], id = carried_ids.data[k];
    if (s > 0 && s <= segment_count) size[std::size_t(s)] += 1;
    if (id > 0) carried_size[id] += 1;
    if (s > 0 && s <= segment_count && id > 0) overlap[{s, id}] += 1;
  }
  std::vector<std::tuple<double, int, int>> candidates;  // (overlap, segment, id)
  for (const auto& [key, pixels] : overlap) {
    const double smaller = std::min(size[std::size_t(key.first)], carried_size[key.second]);
    if (smaller > 0 && pixels >= min_overlap * smaller) candidates.emplace_back(pixels, key.first, key.second);
  }
  std::sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
    return std::get<0>(a) > std::get<0>(b) ||
           (std::get<0>(a) == std::get<0>(b) &&
            std::tie(std::get<1>(a), std::get<2>(a)) < std::tie(std::get<1>(b), std::get<2>(b)));
  });
  std::vector<int> ids(std::size_t(segment_count), 0);
  std::map<int, bool> taken;
  for (const auto& [pixels, segment, id] : candidates) {
    if (ids[std::size_t(segment - 1)] != 0 || taken[id]) continue;
    ids[std::size_t(segment - 1)] = id;
    taken[id] = true;
  }
  for (int& id : ids)
    if (id == 0) id = next_id++;
  return ids;
}

void assignStreamIds(Result& result, const ImageI32& carried_ids, const ImageI32& carried_dormant,
                     const Result& previous, double min_overlap, int memory_pairs) {
  const int m = int(result.segments.size());
  const int first_new = std::max(previous.next_id, 1);
  int next_id = first_new;
  std::vector<int> ids = matchSegmentIds(result.labels, m, carried_ids, min_overlap, next_id);

  // Segments that would get a new id: a dormant id whose region they cover takes precedence.
  result.revived_ids.clear();
  if (!previous.dormant_ids.empty() && carried_dormant.sameSize(result.labels)) {
    ImageI32 fresh(result.width, result.height, 1, 0);
    std::vector<int> fresh_segment;  // fresh index -> segment index
    std::map<int, int> fresh_of_label;
    for (int i = 0; i < m; ++i)
      if (ids[std::size_t(i)] >= first_new) {
        fresh_segment.push_back(i);
        fresh_of_label[i + 1] = int(fresh_segment.size());
      }
    if (!fresh_segment.empty()) {
      for (std::size_t k = 0; k < fresh.data.size(); ++k) {
        const auto it = fresh_of_label.find(result.labels.data[k]);
        if (it != fresh_of_label.end()) fresh.data[k] = it->second;
      }
      const int none = std::numeric_limits<int>::max() / 2;
      int unused = none;
      const std::vector<int> revived =
          matchSegmentIds(fresh, int(fresh_segment.size()), carried_dormant, min_overlap, unused);
      for (std::size_t f = 0; f < fresh_segment.size(); ++f)
        if (revived[f] < none) {
          ids[std::size_t(fresh_segment[f])] = revived[f];
          result.revived_ids.push_back(revived[f]);
        }
      // Keep the new ids dense: renumber the remaining fresh ones.
      next_id = first_new;
      for (std::size_t f = 0; f < fresh_segment.size(); ++f)
        if (revived[f] >= none) ids[std::size_t(fresh_segment[f])] = next_id++;
    }
  }
  for (int& label : result.labels.data)
    if (label > 0 && label <= m) label = ids[std::size_t(label - 1)];
  for (int i = 0; i < m; ++i) result.segments[std::size_t(i)].id = ids[std::size_t(i)];
  result.next_id = next_id;

  // Previous ids without a segment now: merged into the segment that holds most of their carried pixels.
  std::map<int, std::map<int, double>> now_under;  // previous id -> (new id -> pixels)
  std::map<int, double> carried_size;
  for (std::size_t k = 0; k < carried_ids.data.size(); ++k) {
    const int old_id = carried_ids.data[k];
    if (old_id <= 0) continue;
    carried_size[old_id] += 1;
    if (result.labels.data[k] > 0) now_under[old_id][result.labels.data[k]] += 1;
  }
  std::map<int, bool> alive;
  for (const Segment& s : result.segments) alive[s.id] = true;
  result.merged_ids.clear();
  result.ended_ids.clear();
  for (const Segment& s : previous.segments) {
    if (alive.count(s.id)) continue;
    int into = 0;
    double most = 0;
    for (const auto& [id, pixels] : now_under[s.id])
      if (pixels > most) {
        most = pixels;
        into = id;
      }
    if (into > 0 && most >= min_overlap * carried_size[s.id])
      result.merged_ids.emplace_back(s.id, into);
    else
      result.ended_ids.push_back(s.id);
  }

  // Dormant ids: the earlier ones one pair older (not revived, not expired), then the ones that went now.
  result.dormant_ids.clear();
  result.dormant_regions = ImageI32(result.width, result.height, 1, 0);
  if (memory_pairs <= 0) return;
  std::map<int, bool> keep;
  for (const auto& [id, age] : previous.dormant_ids)
    if (!alive.count(id) && age + 1 <= memory_pairs) {
      result.dormant_ids.emplace_back(id, age + 1);
      keep[id] = true;
    }
  std::map<int, bool> went_now;
  for (const Segment& s : previous.segments)
    if (!alive.count(s.id)) {
      result.dormant_ids.emplace_back(s.id, 0);
      went_now[s.id] = true;
    }
  for (std::size_t k = 0; k < result.dormant_regions.data.size(); ++k) {
    const int now = carried_ids.data[k];
    const int earlier = carried_dormant.sameSize(result.labels) ? carried_dormant.data[k] : 0;
    if (now > 0 && went_now.count(now))
      result.dormant_regions.data[k] = now;
    else if (earlier > 0 && keep.count(earlier))
      result.dormant_regions.data[k] = earlier;
  }
}

void offsetSegmentIds(Result& result, int first_id) {
  if (first_id < 1) throw InputError("segment ids: the first id " + std::to_string(first_id) + " is not >= 1");
  const int offset = first_id - 1;
  if (offset == 0) return;
  for (Segment& s : result.segments) s.id += offset;
  for (int& id : result.world.ids) id += offset;
  for (int& label : result.labels.data)
    if (label > 0) label += offset;
  for (int& id : result.dormant_regions.data)
    if (id > 0) id += offset;
  for (auto& [id, into] : result.merged_ids) {
    id += offset;
    into += offset;
  }
  for (int& id : result.ended_ids) id += offset;
  for (int& id : result.revived_ids) id += offset;
  for (auto& dormant : result.dormant_ids) dormant.first += offset;
  result.next_id += offset;
}

}  // namespace mc_flow
