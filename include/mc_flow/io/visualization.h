/**
 * @file visualization.h
 * @brief Pictures of the results (8-bit BGR cv::Mat, ready for cv::imwrite).
 */
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "mc_flow/core/image.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {
namespace io {

/// @brief The BGR colour of a segment id: mc_flow::colourForId (core/palette.h), the one palette of every
/// picture, the nodelet's included; id 0 (outlier / no depth) is dark grey.
cv::Vec3b segmentColor(int id);

/// @brief Soft labels as a colour blend over the grey image: colour = sum_i u_i segmentColor(ids[i]), the outlier
/// plane with id 0's colour, mixed 60 % colour / 40 % image. `ids` holds one segment id per motion label
/// (Result::segments[i].id; labels.count - 1 of them).
cv::Mat segmentationImage(const SoftLabels& labels, const std::vector<int>& ids, const ImageF& intensity);

/// @brief Middlebury colour-wheel coding of a 2-channel flow; hue = direction, saturation = magnitude over
/// `max_magnitude` (0 = the largest finite magnitude in the image after dropping its top 0.5 %, so that a few
/// wild vectors do not wash the picture out; longer vectors are drawn darker). Non-finite flow is black.
cv::Mat flowColorImage(const ImageF& flow, double max_magnitude = 0.0);

/// @brief Depth [m] through a colour map, scaled to [0, max_depth] (0 = the largest valid depth); invalid black.
cv::Mat depthColorImage(const ImageF& depth, double max_depth = 0.0);

/// @brief Grey intensity [0, 1] as BGR.
cv::Mat intensityImage(const ImageF& intensity);
/// @brief A 0/255 mask as BGR.
cv::Mat maskImage(const ImageU8& mask);

/// @brief Tiles (caption, BGR image) into a grid of `columns`, each tile resized to the first tile's size,
/// captions drawn with cv::putText.
cv::Mat overviewPanel(const std::vector<std::pair<std::string, cv::Mat>>& tiles, int columns);

}  // namespace io
}  // namespace mc_flow
