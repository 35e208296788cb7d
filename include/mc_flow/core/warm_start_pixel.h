/**
 * @file warm_start_pixel.h
 * @brief The per-pixel rules of carrying the previous pair's segment ids onto the next frame 1 (warm_start.h's
 * carryIds and carriedLabelsAtLevel), written once for the CPU stage (src/core/warm_start.cpp) and the CUDA one
 * (cuda/warm_start.cu). Depths are frame 1's level-0 depth as the pyramid cleans it (pyramid_pixel.h: 0 where not
 * observed), read through accessors, so both backends carry the same ids bit for bit.
 */
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include "mc_flow/core/host_device.h"
#include "mc_flow/core/pyramid_pixel.h"

namespace mc_flow {
namespace warm_start_pixel {

/// @brief No point has landed on the pixel (above every key of a finite depth).
constexpr std::uint64_t kNoWinner = ~std::uint64_t(0);

/// @brief std::lround for |v| < 2^23 without the library call: v - trunc(v) is exact in float there.
MCFLOW_HOST_DEVICE inline int roundHalfAway(float v) {
  const float t = truncf(v);
  return int(t) + (fabsf(v - t) >= 0.5f ? (v < 0.f ? -1 : 1) : 0);
}

/// @brief The pixel a labelled point of pixel (x, y) lands on, moved by its optical flow (fu, fv); false off the image
/// (NaN too). The bounds are tested before rounding: a point within half a pixel of the border still lands.
MCFLOW_HOST_DEVICE inline bool splatTarget(int x, int y, float fu, float fv, int width, int height, int& tx, int& ty) {
  const float u = float(x) + fu, v = float(y) + fv;
  if (!(u > -1.f && u < float(width) && v > -1.f && v < float(height))) return false;
  tx = roundHalfAway(u);
  ty = roundHalfAway(v);
  return tx >= 0 && ty >= 0 && tx < width && ty < height;
}

/// @brief The splat's key of a point that lands with depth `z_moved` (seen from frame 2's camera) from source pixel
/// `source` (raster index): the depth's bits above the index, so that the smallest key is the nearest point and, of
/// equally near ones, the first in raster order (a positive float's bits order as the float). False where the depth
/// is not finite and positive (the point does not land).
MCFLOW_HOST_DEVICE inline bool splatKey(float z_moved, std::uint32_t source, std::uint64_t& key) {
  if (!(z_moved > 0.f) || !(z_moved <= 3.402823466e38f)) return false;
  std::uint32_t bits;
  std::memcpy(&bits, &z_moved, sizeof bits);
  key = (std::uint64_t(bits) << 32) | std::uint64_t(source);
  return true;
}

/// @brief The moved depth a key holds.
MCFLOW_HOST_DEVICE inline float keyDepth(std::uint64_t key) {
  const std::uint32_t bits = std::uint32_t(key >> 32);
  float z;
  std::memcpy(&z, &bits, sizeof z);
  return z;
}

/// @brief The source pixel a key holds.
MCFLOW_HOST_DEVICE inline std::uint32_t keySource(std::uint64_t key) { return std::uint32_t(key & 0xffffffffu); }

/// @brief Whether the nearest point that landed (moved depth `nearest`) keeps its id at a pixel where frame 1 observed
/// `observed` (cleaned depth, 0 = none): only where the two depths agree within `tolerance` [m].
MCFLOW_HOST_DEVICE inline bool keepsId(float nearest, float observed, double tolerance) {
  return pyramid_pixel::validDepth(observed) && fabsf(nearest - observed) <= tolerance;
}

/// @brief The id pixel (x, y) ends with after the one-pixel gaps that rounding leaves are closed: its carried id, or,
/// where it has none but an observed depth, the most common id of its 8 neighbours whose observed depth is within
/// `tolerance` (the first to reach the highest count, neighbours in raster order) when at least 2 carry it. `id_at`
/// reads the carried ids, `depth_at` the cleaned depth.
template <typename IdAt, typename DepthAt>
MCFLOW_HOST_DEVICE int closedGapId(const IdAt& id_at, const DepthAt& depth_at, int width, int height, int x, int y,
                                   double tolerance) {
  const int own = id_at(x, y);
  const float z = depth_at(x, y);
  if (own > 0 || !pyramid_pixel::validDepth(z)) return own;
  int best_id = 0, best_count = 0, n = 0;
  int ids[8], counts[8];
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int nx = x + dx, ny = y + dy;
      if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
      const int id = id_at(nx, ny);
      const float nz = depth_at(nx, ny);
      if (id <= 0 || !pyramid_pixel::validDepth(nz) || !(fabsf(nz - z) <= tolerance)) continue;
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
  return best_count >= 2 ? best_id : own;
}

/// @brief Of two ids found `count_a` and `count_b` times in a level pixel's block, whether a is the majority's
/// candidate rather than b: the more common, of equally common ones the smaller id (the same whatever the visiting
/// order).
MCFLOW_HOST_DEVICE inline bool beforeInMajority(int count_a, int id_a, int count_b, int id_b) {
  return count_a > count_b || (count_a == count_b && id_a < id_b);
}

/// @brief Whether an id found `count` times in a block of scale x scale input pixels holds the level pixel: at least
/// half of them.
MCFLOW_HOST_DEVICE inline bool holdsLevelPixel(int count, int scale) { return 2 * count >= scale * scale; }

/// @brief The id that holds level pixel (level_x, level_y): of its block of scale x scale input pixels (`id_at(x, y)`
/// reads the carried ids at the input resolution), the id most of them carry (beforeInMajority) when holdsLevelPixel,
/// else 0. `ids` and `counts` are the caller's scratch of at least scale * scale entries.
template <typename IdAt>
MCFLOW_HOST_DEVICE int blockMajorityId(const IdAt& id_at, int level_x, int level_y, int scale, int* ids, int* counts) {
  int n = 0;
  for (int by = 0; by < scale; ++by)
    for (int bx = 0; bx < scale; ++bx) {
      const int id = id_at(level_x * scale + bx, level_y * scale + by);
      if (id <= 0) continue;
      int i = 0;
      while (i < n && ids[i] != id) ++i;
      if (i == n) {
        ids[n] = id;
        counts[n++] = 0;
      }
      ++counts[i];
    }
  int best = -1;
  for (int i = 0; i < n; ++i)
    if (best < 0 || beforeInMajority(counts[i], ids[i], counts[best], ids[best])) best = i;
  return best >= 0 && holdsLevelPixel(counts[best], scale) ? ids[best] : 0;
}

}  // namespace warm_start_pixel
}  // namespace mc_flow
