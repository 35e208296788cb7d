// Stream mode: the previous pair's segments moved into the next frame 1 (forward splatting of the labelled
// points by their scene flow, with a depth test), resampled to a pyramid level, or matched to a cold
// solve's segments by overlap.
#include "mc_flow/core/warm_start.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <tuple>

#include "mc_flow/core/error.h"
#include "mc_flow/core/pyramid_pixel.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/core/warm_start_pixel.h"

namespace mc_flow {

namespace {

// The distinct ids of an id image, each with a dense index (in order of first appearance): a pixel's id is looked up
// in a short list, the last hit first (neighbouring pixels mostly share an id), instead of a tree map per pixel.
class IdIndex {
 public:
  int operator()(int id) {
    if (last_ >= 0 && ids_[std::size_t(last_)] == id) return last_;
    const auto it = std::find(ids_.begin(), ids_.end(), id);
    last_ = int(it - ids_.begin());
    if (it == ids_.end()) ids_.push_back(id);
    return last_;
  }
  int size() const { return int(ids_.size()); }
  int id(int index) const { return ids_[std::size_t(index)]; }

 private:
  std::vector<int> ids_;
  int last_ = -1;
};

// Pixel counts of an id image (its positive ids) against a second image of the same size whose values are mapped to
// slots 1..slots-1 by slot_of (0: none): per id its pixels and its pixels per slot, per slot its pixels. Blocks of rows
// on the OpenMP threads, each with its own tables, added in block order; the counts are integers, so the sums are the
// same whatever the threads (the stream ids of a 640x480 pair took 6 ms on one thread of the GPU machine's host).
struct IdOverlap {
  std::vector<int> ids;                // in ascending order
  std::vector<double> id_pixels;       // per id
  std::vector<double> id_slot_pixels;  // per id, then per slot
  std::vector<double> slot_pixels;     // per slot
  int slots = 0;
  int index(int id) const { return int(std::lower_bound(ids.begin(), ids.end(), id) - ids.begin()); }
  double at(int id_index, int slot) const { return id_slot_pixels[std::size_t(id_index) * slots + slot]; }
};

template <typename SlotOf>
IdOverlap countOverlap(const ImageI32& id_image, const ImageI32& other, int slots, const SlotOf& slot_of) {
  constexpr int kBlocks = 16;
  const int H = id_image.height;
  const std::size_t W = std::size_t(id_image.width);
  struct Block {
    IdIndex ids;
    std::vector<long long> id_pixels, id_slot_pixels, slot_pixels;
  };
  std::vector<Block> blocks(kBlocks);
#pragma omp parallel for schedule(static)
  for (int b = 0; b < kBlocks; ++b) {
    Block& block = blocks[std::size_t(b)];
    block.slot_pixels.assign(std::size_t(slots), 0);
    for (int y = H * b / kBlocks; y < H * (b + 1) / kBlocks; ++y)
      for (std::size_t k = std::size_t(y) * W; k < std::size_t(y + 1) * W; ++k) {
        const int slot = slot_of(other.data[k]);
        ++block.slot_pixels[std::size_t(slot)];
        const int id = id_image.data[k];
        if (id <= 0) continue;
        const int i = block.ids(id);
        if (i == int(block.id_pixels.size())) {
          block.id_pixels.push_back(0);
          block.id_slot_pixels.resize(block.id_slot_pixels.size() + std::size_t(slots), 0);
        }
        ++block.id_pixels[std::size_t(i)];
        ++block.id_slot_pixels[std::size_t(i) * slots + slot];
      }
  }
  IdOverlap out;
  out.slots = slots;
  for (const Block& block : blocks)
    for (int i = 0; i < block.ids.size(); ++i) out.ids.push_back(block.ids.id(i));
  std::sort(out.ids.begin(), out.ids.end());
  out.ids.erase(std::unique(out.ids.begin(), out.ids.end()), out.ids.end());
  std::vector<long long> id_pixels(out.ids.size(), 0), id_slot_pixels(out.ids.size() * std::size_t(slots), 0),
      slot_pixels(std::size_t(slots), 0);
  for (const Block& block : blocks) {
    for (int slot = 0; slot < slots; ++slot) slot_pixels[std::size_t(slot)] += block.slot_pixels[std::size_t(slot)];
    for (int i = 0; i < block.ids.size(); ++i) {
      const std::size_t g = std::size_t(out.index(block.ids.id(i)));
      id_pixels[g] += block.id_pixels[std::size_t(i)];
      for (int slot = 0; slot < slots; ++slot)
        id_slot_pixels[g * slots + slot] += block.id_slot_pixels[std::size_t(i) * slots + slot];
    }
  }
  out.id_pixels.assign(id_pixels.begin(), id_pixels.end());
  out.id_slot_pixels.assign(id_slot_pixels.begin(), id_slot_pixels.end());
  out.slot_pixels.assign(slot_pixels.begin(), slot_pixels.end());
  return out;
}

}  // namespace

ImageI32 carrySegmentIds(const Result& previous, const ImageF& depth, float min_depth, float max_depth,
                         double depth_tolerance) {
  return carryIds(previous.labels, previous, depth, min_depth, max_depth, depth_tolerance);
}

void checkCarryInputs(const ImageI32& ids, const Result& previous, int width, int height) {
  if (previous.width != width || previous.height != height)
    throw InputError("warm start: the previous result is " + std::to_string(previous.width) + "x" +
                     std::to_string(previous.height) + " but the frame is " + std::to_string(width) + "x" +
                     std::to_string(height));
  const std::size_t pixels = std::size_t(width) * std::size_t(height);
  // The splat's key holds a pixel's raster index in 32 bits (warm_start_pixel.h).
  if (pixels > std::size_t(0xffffffffu))
    throw InputError("warm start: " + std::to_string(pixels) + " pixels, at most 4294967295 can be carried");
  auto check = [&](const char* what, std::size_t values, std::size_t expected) {
    if (values != expected)
      throw InputError(std::string("warm start: the previous result's ") + what + " has " + std::to_string(values) +
                       " values, expected " + std::to_string(expected) + " for " + imageSizeText(width, height));
  };
  check("id image", ids.data.size(), pixels);
  check("optical flow", previous.optical_flow.data.size(), pixels * 2);
  check("moved depth", previous.moved_depth.data.size(), pixels);
}

ImageI32 carryIds(const ImageI32& ids, const Result& previous, const ImageF& depth, float min_depth, float max_depth,
                  double depth_tolerance) {
  using namespace warm_start_pixel;
  const int W = depth.width, H = depth.height;
  if (depth.channels != 1 || depth.data.size() != std::size_t(W) * H)
    throw InputError("warm start: the frame's depth has " + std::to_string(depth.channels) + " channels and " +
                     std::to_string(depth.data.size()) + " values for " + imageSizeText(W, H));
  checkCarryInputs(ids, previous, W, H);
  // Forward splat with a depth buffer: the nearest moved point wins a pixel, and of equally near ones the first in
  // raster order (as a serial splat that replaces only on a nearer point). On the threads: each pixel keeps the
  // minimum key (warm_start_pixel.h's splatKey).
  const std::size_t pixels = std::size_t(W) * std::size_t(H);
  std::vector<std::atomic<std::uint64_t>> winner(pixels);
#pragma omp parallel for schedule(static)
  for (long k = 0; k < long(pixels); ++k) winner[std::size_t(k)].store(kNoWinner, std::memory_order_relaxed);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      int tx = 0, ty = 0;
      std::uint64_t key = 0;
      if (ids(x, y) <= 0 ||
          !splatTarget(x, y, previous.optical_flow(x, y, 0), previous.optical_flow(x, y, 1), W, H, tx, ty) ||
          !splatKey(previous.moved_depth(x, y), std::uint32_t(std::size_t(y) * std::size_t(W) + x), key))
        continue;
      std::atomic<std::uint64_t>& best = winner[std::size_t(ty) * std::size_t(W) + std::size_t(tx)];
      std::uint64_t seen = best.load(std::memory_order_relaxed);
      while (key < seen && !best.compare_exchange_weak(seen, key, std::memory_order_relaxed)) {
      }
    }
  // The depth the pyramid's level 0 holds (pyramid_pixel.h's rule, 0 where none): a GPU solve has it on the device.
  ImageF observed(W, H, 1);
#pragma omp parallel for schedule(static)
  for (long k = 0; k < long(pixels); ++k)
    observed.data[std::size_t(k)] = pyramid_pixel::cleanDepth(depth.data[std::size_t(k)], min_depth, max_depth);
  ImageI32 carried(W, H, 1, 0);
#pragma omp parallel for schedule(static)
  for (long k = 0; k < long(pixels); ++k) {
    const std::uint64_t key = winner[std::size_t(k)].load(std::memory_order_relaxed);
    if (key == kNoWinner) continue;
    const int id = ids.data[keySource(key)];
    if (keepsId(keyDepth(key), observed.data[std::size_t(k)], depth_tolerance)) carried.data[std::size_t(k)] = id;
  }
  // Close the one-pixel gaps that rounding leaves where a surface comes closer (it covers more pixels).
  ImageI32 closed(W, H, 1, 0);
  const auto id_at = [&](int x, int y) { return carried(x, y); };
  const auto depth_at = [&](int x, int y) { return observed(x, y); };
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) closed(x, y) = closedGapId(id_at, depth_at, W, H, x, y, depth_tolerance);
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
  // Each level pixel's majority id (0: none, -1: no depth), in parallel.
  ImageI32 majority(w, h, 1, 0);
  const auto id_at = [&](int x, int y) { return carried_ids(x, y); };
#pragma omp parallel
  {
    std::vector<int> ids(std::size_t(scale) * std::size_t(scale)), counts(ids.size());  // per thread
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        majority(x, y) = std::isfinite(level_points(x, y, 2))
                             ? warm_start_pixel::blockMajorityId(id_at, x, y, scale, ids.data(), counts.data())
                             : -1;
  }
  return carriedLabelsFromMajority(majority);
}

CarriedLabels carriedLabelsFromMajority(const ImageI32& majority) {
  CarriedLabels out;
  out.hard = ImageI32(majority.width, majority.height, 1, -1);
  // The label indices in order of first appearance in raster order, so that they do not depend on the threads that
  // found the majorities (IdIndex: a short list, the last hit first, instead of a tree map per pixel).
  IdIndex index_of_id;
  for (std::size_t k = 0; k < majority.data.size(); ++k) {
    const int id = majority.data[k];
    if (id < 0) continue;
    ++out.valid;
    if (id == 0) continue;
    out.hard.data[k] = index_of_id(id);
    ++out.covered;
  }
  for (int i = 0; i < index_of_id.size(); ++i) out.ids.push_back(index_of_id.id(i));
  return out;
}

CarriedSegments carrySegments(const Result& previous, const ImageF& depth, const ImageF* level_points, int scale,
                              const Config& config) {
  CarriedSegments out;
  const float min_depth = float(config.min_depth), max_depth = float(config.max_depth);
  out.ids = carrySegmentIds(previous, depth, min_depth, max_depth, config.warm_depth_tolerance);
  if (!previous.dormant_ids.empty())
    out.dormant =
        carryIds(previous.dormant_regions, previous, depth, min_depth, max_depth, config.warm_depth_tolerance);
  if (level_points) out.labels = carriedLabelsAtLevel(out.ids, *level_points, scale);
  return out;
}

namespace {

// matchSegmentIds, with the counts it matched on (`counts`: slots the segments 1..segment_count, 0 a label outside).
std::vector<int> matchSegmentIdsCounted(const ImageI32& labels, int segment_count, const ImageI32& carried_ids,
                                        double min_overlap, int& next_id, IdOverlap& counts) {
  if (labels.width != carried_ids.width || labels.height != carried_ids.height)
    throw InputError("segment ids: labels are " + std::to_string(labels.width) + "x" + std::to_string(labels.height) +
                     ", carried ids " + std::to_string(carried_ids.width) + "x" + std::to_string(carried_ids.height));
  counts = countOverlap(carried_ids, labels, segment_count + 1,
                        [segment_count](int s) { return s > 0 && s <= segment_count ? s : 0; });
  std::vector<std::tuple<double, int, int>> candidates;  // (overlap, segment, id)
  for (int c = 0; c < int(counts.ids.size()); ++c)
    for (int segment = 1; segment <= segment_count; ++segment) {
      const double pixels = counts.at(c, segment);
      const double smaller = std::min(counts.slot_pixels[std::size_t(segment)], counts.id_pixels[std::size_t(c)]);
      if (pixels > 0 && smaller > 0 && pixels >= min_overlap * smaller)
        candidates.emplace_back(pixels, segment, counts.ids[std::size_t(c)]);
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

}  // namespace

std::vector<int> matchSegmentIds(const ImageI32& labels, int segment_count, const ImageI32& carried_ids,
                                 double min_overlap, int& next_id) {
  IdOverlap counts;
  return matchSegmentIdsCounted(labels, segment_count, carried_ids, min_overlap, next_id, counts);
}

void assignStreamIds(Result& result, const ImageI32& carried_ids, const ImageI32& carried_dormant,
                     const Result& previous, double min_overlap, int memory_pairs) {
  const int m = int(result.segments.size());
  const int first_new = std::max(previous.next_id, 1);
  int next_id = first_new;
  IdOverlap counts;  // carried ids against the segments 1..m
  std::vector<int> ids = matchSegmentIdsCounted(result.labels, m, carried_ids, min_overlap, next_id, counts);

  // Segments that would get a new id: a dormant id whose region they cover takes precedence.
  result.revived_ids.clear();
  if (!previous.dormant_ids.empty() && carried_dormant.sameSize(result.labels)) {
    std::vector<int> fresh_segment;                          // fresh index -> segment index
    std::vector<int> fresh_of_label(std::size_t(m) + 1, 0);  // label 1..m -> fresh index (1..), 0: not fresh
    for (int i = 0; i < m; ++i)
      if (ids[std::size_t(i)] >= first_new) {
        fresh_segment.push_back(i);
        fresh_of_label[std::size_t(i) + 1] = int(fresh_segment.size());
      }
    if (!fresh_segment.empty()) {
      ImageI32 fresh(result.width, result.height, 1);
      const long pixels = long(fresh.data.size());
#pragma omp parallel for schedule(static)
      for (long k = 0; k < pixels; ++k) {
        const int label = result.labels.data[std::size_t(k)];
        fresh.data[std::size_t(k)] = label > 0 && label <= m ? fresh_of_label[std::size_t(label)] : 0;
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
  {
    int* const labels = result.labels.data.data();
    const long pixels = long(result.labels.data.size());
#pragma omp parallel for schedule(static)
    for (long k = 0; k < pixels; ++k)
      if (labels[k] > 0 && labels[k] <= m) labels[k] = ids[std::size_t(labels[k] - 1)];
  }
  for (int i = 0; i < m; ++i) result.segments[std::size_t(i)].id = ids[std::size_t(i)];
  result.next_id = next_id;

  // Previous ids without a segment now: merged into the segment that holds most of their carried pixels. Slots: the
  // new ids in ascending order (1..), 0 for no segment.
  std::vector<int> now_ids;
  for (const Segment& s : result.segments) now_ids.push_back(s.id);
  std::sort(now_ids.begin(), now_ids.end());
  now_ids.erase(std::unique(now_ids.begin(), now_ids.end()), now_ids.end());
  // The counts of the match above with each segment's slot moved to its new id's (the relabelling maps the segments
  // one to one onto their ids: the same counts as counting the relabelled image again).
  IdOverlap under;
  under.ids = counts.ids;
  under.id_pixels = counts.id_pixels;
  under.slots = int(now_ids.size()) + 1;
  under.slot_pixels.assign(std::size_t(under.slots), 0.0);
  under.id_slot_pixels.assign(under.ids.size() * std::size_t(under.slots), 0.0);
  for (int segment = 0; segment <= m; ++segment) {
    const int slot =
        segment == 0
            ? 0
            : int(std::lower_bound(now_ids.begin(), now_ids.end(), ids[std::size_t(segment - 1)]) - now_ids.begin()) +
                  1;
    under.slot_pixels[std::size_t(slot)] += counts.slot_pixels[std::size_t(segment)];
    for (std::size_t c = 0; c < under.ids.size(); ++c)
      under.id_slot_pixels[c * std::size_t(under.slots) + std::size_t(slot)] += counts.at(int(c), segment);
  }
  std::map<int, bool> alive;
  for (const Segment& s : result.segments) alive[s.id] = true;
  result.merged_ids.clear();
  result.ended_ids.clear();
  for (const Segment& s : previous.segments) {
    if (alive.count(s.id)) continue;
    // The new id holding most of its pixels; ties to the smaller id (the slots ascend with the ids).
    int into = 0;
    double most = 0, size = 0;
    const int c = under.index(s.id);
    if (c < int(under.ids.size()) && under.ids[std::size_t(c)] == s.id) {
      size = under.id_pixels[std::size_t(c)];
      for (int slot = 1; slot < under.slots; ++slot)
        if (under.at(c, slot) > most) {
          most = under.at(c, slot);
          into = now_ids[std::size_t(slot - 1)];
        }
    }
    if (into > 0 && most >= min_overlap * size)
      result.merged_ids.emplace_back(s.id, into);
    else
      result.ended_ids.push_back(s.id);
  }

  // Dormant ids: the earlier ones one pair older (not revived, not expired), then the ones that went now.
  result.dormant_ids.clear();
  // Zeros in the memory the result came with (a recycled result's: no fresh pages per pair).
  result.dormant_regions.width = result.width;
  result.dormant_regions.height = result.height;
  result.dormant_regions.channels = 1;
  result.dormant_regions.data.assign(std::size_t(result.width) * std::size_t(result.height), 0);
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
  // Per pixel, whether its carried id went now or its dormant id is kept (sorted lists: pixels on the threads).
  std::vector<int> went, kept;
  for (const auto& [id, yes] : went_now) went.push_back(id);
  for (const auto& [id, yes] : keep) kept.push_back(id);
  const bool has_earlier = carried_dormant.sameSize(result.labels);
  auto holds = [](const std::vector<int>& sorted, int id) {
    return std::binary_search(sorted.begin(), sorted.end(), id);
  };
  int* const regions = result.dormant_regions.data.data();
  const long pixels = long(result.dormant_regions.data.size());
#pragma omp parallel for schedule(static)
  for (long k = 0; k < pixels; ++k) {
    const int now = carried_ids.data[std::size_t(k)];
    if (now > 0 && holds(went, now)) {
      regions[k] = now;
      continue;
    }
    const int earlier = has_earlier ? carried_dormant.data[std::size_t(k)] : 0;
    if (earlier > 0 && holds(kept, earlier)) regions[k] = earlier;
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
