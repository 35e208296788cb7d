/**
 * @file segment_tracker.h
 * @brief Keeps segment ids (and so their display colours) stable across consecutive pairs. ROS-free.
 *
 * The solver numbers the segments of each pair 1..m afresh. Pair k labels the pixels of frame k-1 and
 * pair k+1 labels those of frame k, so the tracker moves the previous pair's persistent-id image forward
 * by the previous pair's optical flow (onto frame k) and matches the new segments to the old ids by pixel
 * overlap: the pairs with the largest overlap are matched first, each id at most once, and a new segment
 * that overlaps no old one enough gets a fresh id.
 */
#pragma once

#include <cstdint>
#include <vector>

#include "mc_flow/core/image.h"

namespace mc_flow_ros {

/// @brief An 8-bit RGB display colour.
struct Rgb8 {
  std::uint8_t r = 0, g = 0, b = 0;
};

/// @brief Display colour of a persistent segment id: well separated hues for neighbouring ids; id 0
/// (outlier / no depth) is dark grey.
Rgb8 colourForId(std::uint32_t id);

/// @brief Assigns persistent ids to the segments of consecutive pairs.
class SegmentTracker {
 public:
  struct Options {
    /// A new segment inherits an old id when they share at least this fraction of the smaller of the two
    /// regions (pixels, after moving the old region by its optical flow).
    double min_overlap = 0.3;
  };

  SegmentTracker() : SegmentTracker(Options()) {}
  explicit SegmentTracker(const Options& options);

  /// @brief Matches one pair's segments to the ids of the previous pair.
  /// @param labels solver labels of the pair (1..segment_count; 0 = outlier or no depth), frame-1 pixels.
  /// @param segment_count number of motion segments m of the pair.
  /// @param optical_flow the pair's 2-channel optical flow [px] (NaN where unknown), used to move this
  ///        pair's ids onto the next pair's pixels; an empty image means no motion.
  /// @return persistent id of solver label i at index i-1 (size segment_count).
  std::vector<std::uint32_t> update(const mc_flow::ImageI32& labels, int segment_count,
                                    const mc_flow::ImageF& optical_flow);

  /// @brief Forgets the previous pair (stream reset, resolution change); ids keep increasing.
  void reset();

  /// @brief Persistent-id image of the last pair moved onto the next pair's pixels (0 = unknown).
  const mc_flow::ImageI32& predictedIds() const { return predicted_ids_; }
  /// @brief The id the next new segment will get.
  std::uint32_t nextId() const { return next_id_; }

 private:
  Options options_;
  mc_flow::ImageI32 predicted_ids_;
  std::uint32_t next_id_ = 1;
};

}  // namespace mc_flow_ros
