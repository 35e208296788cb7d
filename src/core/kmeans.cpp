#include "mc_flow/core/kmeans.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "mc_flow/core/error.h"
#include "mc_flow/core/nearest_centre.h"

namespace mc_flow {

namespace {

struct ValidPoints {
  std::vector<Eigen::Vector3f> points;
  std::vector<int> pixel;  ///< index into the image of each point
};

void requirePointImage(const char* what, const ImageF& points) {
  if (points.channels != 3)
    throw InputError(std::string(what) + ": point image has " + std::to_string(points.channels) +
                     " channels, expected 3");
}

ValidPoints collectValidPoints(const ImageF& image) {
  ValidPoints v;
  const std::size_t n = image.pixelCount();
  v.points.reserve(n);
  v.pixel.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float* p = image.ptr() + 3 * i;
    if (std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])) {
      v.points.emplace_back(p[0], p[1], p[2]);
      v.pixel.push_back(int(i));
    }
  }
  return v;
}

int nearestCentre(const Eigen::Vector3f& p, const std::vector<Eigen::Vector3f>& centres) {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "centres are read as x, y, z triples");
  return nearestCentreIndex(p.x(), p.y(), p.z(), centres.front().data(), int(centres.size()));
}

// Below this many points the assignment runs on one thread: a parallel region's start costs more than it saves (a warm
// start's K-means of the pixels no carried segment covers has a few hundred to a few thousand).
constexpr long kParallelAssignPoints = 16384;

void assignAll(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& centres,
               std::vector<int>& assignment) {
  const long n = long(points.size());
#pragma omp parallel for schedule(static) if (n >= kParallelAssignPoints)
  for (long i = 0; i < n; ++i) assignment[std::size_t(i)] = nearestCentre(points[std::size_t(i)], centres);
}

float squaredDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& centre) {
  return kmeansSquaredDistance(p.x(), p.y(), p.z(), centre.data());
}

/// k-means++ seeding; stops early when every remaining point coincides with a centre.
std::vector<Eigen::Vector3f> seedCentres(const std::vector<Eigen::Vector3f>& points, int k, unsigned seed) {
  const std::vector<double> draws = kmeansSeedingDraws(seed, k);
  const std::size_t n = points.size();
  std::vector<Eigen::Vector3f> centres;
  centres.reserve(std::size_t(k));
  centres.push_back(points[std::min(n - 1, std::size_t(draws[0] * double(n)))]);
  std::vector<double> dist2(n);
  for (std::size_t i = 0; i < n; ++i) dist2[i] = squaredDistance(points[i], centres[0]);
  while (int(centres.size()) < k) {
    double total = 0;
    for (const double d : dist2) total += d;
    if (!(total > 0)) break;
    const double target = draws[centres.size()] * total;
    double running = 0;
    std::size_t chosen = n;
    for (std::size_t i = 0; i < n; ++i) {
      running += dist2[i];
      if (running > target && dist2[i] > 0) {
        chosen = i;
        break;
      }
    }
    if (chosen == n)  // rounding at the end of the scan: take the last point not yet covered
      for (std::size_t i = n; i-- > 0;)
        if (dist2[i] > 0) {
          chosen = i;
          break;
        }
    centres.push_back(points[chosen]);
    for (std::size_t i = 0; i < n; ++i)
      dist2[i] = std::min(dist2[i], double(squaredDistance(points[i], centres.back())));
  }
  return centres;
}

/// Means of the clusters (double accumulation, serial: the result does not depend on the thread count).
/// Empty clusters are dropped. Returns the largest centre displacement.
double updateCentres(const std::vector<Eigen::Vector3f>& points, const std::vector<int>& assignment,
                     std::vector<Eigen::Vector3f>& centres) {
  std::vector<Eigen::Vector3d> sums(centres.size(), Eigen::Vector3d::Zero());
  std::vector<std::size_t> counts(centres.size(), 0);
  for (std::size_t i = 0; i < points.size(); ++i) {
    sums[std::size_t(assignment[i])] += points[i].cast<double>();
    ++counts[std::size_t(assignment[i])];
  }
  std::vector<Eigen::Vector3f> updated;
  updated.reserve(centres.size());
  double moved = 0;
  for (std::size_t c = 0; c < centres.size(); ++c) {
    if (counts[c] == 0) continue;
    const Eigen::Vector3f mean = (sums[c] / double(counts[c])).cast<float>();
    moved = std::max(moved, double(std::sqrt(squaredDistance(mean, centres[c]))));
    updated.push_back(mean);
  }
  if (updated.size() != centres.size()) moved = std::numeric_limits<double>::infinity();
  centres.swap(updated);
  return moved;
}

}  // namespace

std::vector<double> kmeansSeedingDraws(unsigned seed, int k) {
  std::mt19937 rng(seed);
  std::vector<double> draws(std::size_t(std::max(k, 0)));
  for (double& d : draws) d = double(rng()) / 4294967296.0;
  return draws;
}

KMeansPointsResult kmeansPointList(const std::vector<Eigen::Vector3f>& points, int k, int max_iterations,
                                   double tolerance_m, unsigned seed) {
  if (k < 1) throw InputError("kmeansPoints: k = " + std::to_string(k) + " must be >= 1");
  if (max_iterations < 0)
    throw InputError("kmeansPoints: max_iterations = " + std::to_string(max_iterations) + " must be >= 0");
  KMeansPointsResult result;
  if (points.empty()) return result;
  result.centres = seedCentres(points, k, seed);
  result.assignment.assign(points.size(), 0);
  for (int it = 1; it <= max_iterations; ++it) {
    assignAll(points, result.centres, result.assignment);
    const double moved = updateCentres(points, result.assignment, result.centres);
    result.iterations = it;
    if (moved <= tolerance_m) break;
  }
  // Final assignment to the returned centres; a centre that ends up without points is dropped.
  for (;;) {
    assignAll(points, result.centres, result.assignment);
    std::vector<char> used(result.centres.size(), 0);
    for (const int a : result.assignment) used[std::size_t(a)] = 1;
    std::vector<Eigen::Vector3f> kept;
    for (std::size_t c = 0; c < result.centres.size(); ++c)
      if (used[c]) kept.push_back(result.centres[c]);
    if (kept.size() == result.centres.size()) break;
    result.centres.swap(kept);
  }
  return result;
}

KMeansResult kmeansPoints(const ImageF& points, int k, int max_iterations, double tolerance_m, unsigned seed) {
  requirePointImage("kmeansPoints", points);
  const ValidPoints valid = collectValidPoints(points);
  KMeansPointsResult list = kmeansPointList(valid.points, k, max_iterations, tolerance_m, seed);
  KMeansResult result;
  result.assignment = ImageI32(points.width, points.height, 1, -1);
  result.centres = std::move(list.centres);
  result.iterations = list.iterations;
  for (std::size_t i = 0; i < valid.points.size(); ++i)
    result.assignment.data[std::size_t(valid.pixel[i])] = list.assignment[i];
  return result;
}

ImageI32 assignToNearestCentre(const ImageF& points, const std::vector<Eigen::Vector3f>& centres) {
  requirePointImage("assignToNearestCentre", points);
  ImageI32 out(points.width, points.height, 1, -1);
  if (centres.empty()) return out;
  const int w = points.width, h = points.height;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float* p = &points(x, y, 0);
      if (std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))
        out(x, y) = nearestCentre(Eigen::Vector3f(p[0], p[1], p[2]), centres);
    }
  return out;
}

}  // namespace mc_flow
