/**
 * @file warm_start.h
 * @brief Stream mode: the previous pair's segments carried into the next pair's frame 1, for a warm start
 * (initial labels and motions) and for persistent segment ids.
 *
 * Pair k solves frames (k-1, k) and labels frame k-1's pixels; pair k+1 labels frame k's. The previous
 * pair's scene flow moves each labelled point of frame k-1 to where it is in frame k, which says which
 * segment each pixel of frame k continues. Design: docs/ALGORITHM.md, "Stream mode".
 */
#pragma once

#include <vector>

#include "mc_flow/core/image.h"

namespace mc_flow {

struct Result;
struct Config;

/// @brief The previous pair's segment ids on the next pair's frame-1 pixels (input resolution), 0 where
/// no segment arrives. Each labelled point of the previous frame 1 is moved by its scene flow and
/// projected (the nearest point wins a pixel); a pixel keeps the id only where the moved point's depth is
/// within `depth_tolerance` [m] of the depth observed there (`depth`: the next frame 1's input depth [m], observed
/// where within [min_depth, max_depth], as the solver's pyramid takes it). One-pixel gaps between splatted points are
/// closed from neighbours at a similar depth. The CPU's carry (SolveBackend::carrySegments' default); the CUDA
/// backend's is cuda/warm_start.cu on its level-0 depth, with the same rules (warm_start_pixel.h). Throws InputError on
/// mismatched sizes.
ImageI32 carrySegmentIds(const Result& previous, const ImageF& depth, float min_depth, float max_depth,
                         double depth_tolerance);
/// @brief The same for another id image on the previous pair's frame-1 pixels (e.g. its dormant regions).
ImageI32 carryIds(const ImageI32& ids, const Result& previous, const ImageF& depth, float min_depth, float max_depth,
                  double depth_tolerance);

/// @brief Carried ids as hard initial labels of a pyramid level.
struct CarriedLabels {
  ImageI32 hard;         ///< motion label index per level pixel, -1 = uncovered or no depth
  std::vector<int> ids;  ///< segment id of motion label i
  int covered = 0;       ///< level pixels with valid depth and a carried label
  int valid = 0;         ///< level pixels with valid depth
  double coverage() const { return valid > 0 ? double(covered) / valid : 0.0; }
};

/// @brief Each pixel of the level (3D points `level_points`, `scale` input pixels per level pixel, a power
/// of two) takes the id most of its input pixels carry, when they are at least half of them.
CarriedLabels carriedLabelsAtLevel(const ImageI32& carried_ids, const ImageF& level_points, int scale);

/// @brief carriedLabelsAtLevel's second half: the label indices of a level's majority ids (-1: no depth, 0: none, else
/// the id), in raster order of first appearance.
CarriedLabels carriedLabelsFromMajority(const ImageI32& majority);

/// @brief Checks what carryIds reads of `ids` and `previous` against a frame of width x height; throws InputError
/// naming the sizes.
void checkCarryInputs(const ImageI32& ids, const Result& previous, int width, int height);

/// @brief What a stream pair takes over from the previous pair: its segment ids and (where it has dormant ids) its
/// dormant regions carried onto this frame 1 (carryIds with Config::min_depth, max_depth and warm_depth_tolerance), and
/// the carried ids as hard labels of the label level (carriedLabelsAtLevel; empty when not asked for).
struct CarriedSegments {
  ImageI32 ids, dormant;
  CarriedLabels labels;
};

/// @brief CarriedSegments on the host: `depth` is the next frame 1's input depth; `level_points` (null: no labels) the
/// label level's points, `scale` input pixels per level pixel. SolveBackend::carrySegments' default.
CarriedSegments carrySegments(const Result& previous, const ImageF& depth, const ImageF* level_points, int scale,
                              const Config& config);

/// @brief Persistent ids by overlap: segment i (labels 1..m in `labels`, 0 = none) takes the
/// carried id it overlaps most when the overlap is at least `min_overlap` of the smaller of the two regions
/// (largest overlaps matched first, each id once); the others get next_id, next_id + 1, ... (advanced).
std::vector<int> matchSegmentIds(const ImageI32& labels, int segment_count, const ImageI32& carried_ids,
                                 double min_overlap, int& next_id);

/// @brief Gives a stream pair's segments their persistent ids: each previous id goes to the segment that
/// overlaps its carried pixels most (matchSegmentIds with `min_overlap`), the others get new ids from
/// previous.next_id on. A previous id that lost its segment is reported in Result::merged_ids when most of
/// its carried pixels now belong to one segment (at least `min_overlap` of them), else in Result::ended_ids.
/// A segment that would get a new id first takes back a dormant id (Result::dormant_ids of `previous`) whose
/// carried region (`carried_dormant`) it overlaps enough (Result::revived_ids). Updates the dormant ids and
/// regions (kept `memory_pairs` pairs). Sets Result::next_id. `result` has labels 1..m on entry.
void assignStreamIds(Result& result, const ImageI32& carried_ids, const ImageI32& carried_dormant,
                     const Result& previous, double min_overlap, int memory_pairs);

/// @brief Adds `first_id` - 1 to every segment id of `result` (Segment::id, Result::labels > 0, next_id, the
/// merged, ended, revived and dormant ids, Result::dormant_regions > 0), so that a pair solved alone (ids 1..m)
/// numbers its segments first_id, first_id + 1, ... SequencePipeline uses it after a reset, so that a new
/// sequence does not reuse the ids of the ones before. Throws InputError when `first_id` < 1.
void offsetSegmentIds(Result& result, int first_id);

}  // namespace mc_flow
