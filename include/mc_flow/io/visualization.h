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

/// @brief A fixed, distinct BGR colour for segment plane i (0-based); the same i always gives the same colour.
cv::Vec3b segmentColor(int index);

/// @brief Soft labels as a colour blend over the grey image: colour = sum_i u_i colour_i (outlier plane black),
/// mixed 60 % colour / 40 % image.
cv::Mat segmentationImage(const SoftLabels& labels, const ImageF& intensity);

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
