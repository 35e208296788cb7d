/**
 * @file palette.h
 * @brief Display colours of segment ids, one palette for every picture (the CLI's and the nodelet's).
 */
#pragma once

#include <cstdint>

namespace mc_flow {

/// @brief An 8-bit RGB display colour.
struct Rgb8 {
  std::uint8_t r = 0, g = 0, b = 0;
};

/// @brief Display colour of a persistent segment id: well separated hues for neighbouring ids; id 0
/// (outlier / no depth) is dark grey.
Rgb8 colourForId(std::uint32_t id);

}  // namespace mc_flow
