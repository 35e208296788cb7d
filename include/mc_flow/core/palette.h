/**
 * @file palette.h
 * @brief Display colours of segment ids, one palette for every picture (the CLI's and the nodelet's).
 */
#pragma once

#include <cstdint>
#include <vector>

#include "mc_flow/core/image.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

/// @brief An 8-bit RGB display colour.
struct Rgb8 {
  std::uint8_t r = 0, g = 0, b = 0;
};

/// @brief Display colour of a persistent segment id: well separated hues for neighbouring ids; id 0
/// (outlier / no depth) is dark grey.
Rgb8 colourForId(std::uint32_t id);

/// @brief The static world's display colour: every world segment alike (a pale steel blue, so that what moves stands
/// out in its own hue).
inline constexpr Rgb8 kWorldColour{150, 170, 190};

/// @brief kWorldColour for an id of `world_ids`, else colourForId(id).
Rgb8 displayColour(std::uint32_t id, const std::vector<int>& world_ids);

/// @brief The segmentation picture (3 channels, RGB): per pixel the segment colours weighted by the soft labels
/// (plane i in displayColour(ids[i], world_ids), the outlier plane in id 0's grey), mixed `blend` colour / (1 - blend)
/// image grey (`intensity` in [0, 1]; mid grey where it is null or of another size). `ids` holds labels.count - 1 ids.
/// Throws InputError naming the counts when they do not fit. The one renderer of the CLI's and the nodelet's
/// pictures.
ImageU8 segmentationPicture(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity,
                            double blend, const std::vector<int>& world_ids = {});
/// @brief segmentationPicture into caller memory: `rgb` holds labels.width * labels.height * 3 bytes, rows top to
/// bottom, R G B per pixel (a ROS image message's data, say).
void segmentationPictureInto(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity,
                             double blend, const std::vector<int>& world_ids, std::uint8_t* rgb);

/// @brief segmentationPictureInto by ranges of rows, for callers that fill several outputs in one parallel region.
/// Holds references to `labels`, `intensity` and a copy of the colours; throws InputError as segmentationPicture does.
class SegmentationPainter {
 public:
  SegmentationPainter(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity, double blend,
                      const std::vector<int>& world_ids);
  /// Rows [first_row, end_row) of the picture into `rgb` (the whole picture's memory, as segmentationPictureInto's).
  void paintRows(int first_row, int end_row, std::uint8_t* rgb) const;

 private:
  const SoftLabels& labels_;
  const ImageF* intensity_;  // null where there is none of the labels' size
  double blend_;
  std::vector<Rgb8> colours_;          // per plane, the outlier plane last
  std::vector<double> colour_values_;  // the same as r, g, b doubles (the AVX2 rows' broadcasts)
};

}  // namespace mc_flow
