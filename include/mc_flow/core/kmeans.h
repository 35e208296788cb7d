/**
 * @file kmeans.h
 * @brief Initial labels: K-means (Lloyd) on the 3D points, deterministic for a given seed.
 */
#pragma once

#include <Eigen/Core>
#include <vector>

#include "mc_flow/core/image.h"

namespace mc_flow {

struct KMeansResult {
  std::vector<Eigen::Vector3f> centres;
  ImageI32 assignment;  ///< cluster index per pixel, -1 where the point is invalid
  int iterations = 0;
};

/// @brief K-means on the valid points of a 3 channel point image. Seeds: k-means++ with a PRNG seeded
/// by `seed` (same input + seed = same output). Returns fewer centres when fewer distinct points exist.
KMeansResult kmeansPoints(const ImageF& points, int k, int max_iterations, double tolerance_m, unsigned seed);

/// @brief kmeansPoints on a list of finite points (in the order kmeansPoints would take an image's valid points): the
/// same centres, and each point's cluster.
struct KMeansPointsResult {
  std::vector<Eigen::Vector3f> centres;
  std::vector<int> assignment;  ///< cluster index per point
  int iterations = 0;
};
KMeansPointsResult kmeansPointList(const std::vector<Eigen::Vector3f>& points, int k, int max_iterations,
                                   double tolerance_m, unsigned seed);

/// @brief The k uniform draws in [0, 1) of kmeansPoints' k-means++ seeding from `seed` (draw 0 picks the first centre,
/// draw j the (j+1)-th), from a std::mt19937 and the raw-output conversion u / 2^32, which, unlike
/// std::uniform_real_distribution, every standard library computes alike. The CUDA backend's K-means takes them as
/// an argument, so both seed from the same numbers.
std::vector<double> kmeansSeedingDraws(unsigned seed, int k);

/// @brief Nearest-centre assignment of each valid point (-1 where invalid).
ImageI32 assignToNearestCentre(const ImageF& points, const std::vector<Eigen::Vector3f>& centres);

}  // namespace mc_flow
