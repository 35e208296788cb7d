#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <random>

#include "mc_flow/core/error.h"
#include "mc_flow/core/kmeans.h"
#include "mc_flow/core/nearest_centre.h"

namespace mc_flow {
namespace {

const Eigen::Vector3f kBlobCentres[3] = {{-1.f, 0.f, 2.f}, {1.f, 0.5f, 3.f}, {0.f, -1.f, 4.f}};

/// 60x40 point image: three blobs (sigma 2 cm) laid out in vertical stripes, plus a few invalid pixels.
ImageF blobImage(ImageI32& truth) {
  const int w = 60, h = 40;
  ImageF points(w, h, 3);
  truth = ImageI32(w, h, 1, -1);
  std::mt19937 rng(11);
  std::normal_distribution<float> noise(0.f, 0.02f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float* p = &points(x, y, 0);
      if ((x * 13 + y * 7) % 29 == 0) {
        p[0] = p[1] = p[2] = std::numeric_limits<float>::quiet_NaN();
        continue;
      }
      const int blob = x / 20;
      truth(x, y) = blob;
      for (int c = 0; c < 3; ++c) p[c] = kBlobCentres[blob][c] + noise(rng);
    }
  return points;
}

TEST(KMeans, RecoversWellSeparatedBlobs) {
  ImageI32 truth;
  const ImageF points = blobImage(truth);
  const KMeansResult r = kmeansPoints(points, 3, 20, 1e-4, 1);
  ASSERT_EQ(r.centres.size(), 3u);
  // Every blob maps to exactly one cluster and vice versa.
  std::map<int, int> blob_to_cluster;
  for (std::size_t k = 0; k < truth.data.size(); ++k) {
    if (truth.data[k] < 0) {
      EXPECT_EQ(r.assignment.data[k], -1);
      continue;
    }
    const int cluster = r.assignment.data[k];
    ASSERT_GE(cluster, 0);
    auto [it, inserted] = blob_to_cluster.emplace(truth.data[k], cluster);
    EXPECT_EQ(it->second, cluster) << "blob " << truth.data[k] << " split";
  }
  ASSERT_EQ(blob_to_cluster.size(), 3u);
  std::map<int, int> cluster_to_blob;
  for (auto [blob, cluster] : blob_to_cluster) EXPECT_TRUE(cluster_to_blob.emplace(cluster, blob).second);
  for (auto [blob, cluster] : blob_to_cluster)
    EXPECT_LT((r.centres[std::size_t(cluster)] - kBlobCentres[blob]).norm(), 0.01f);
  EXPECT_GE(r.iterations, 1);
}

TEST(KMeans, SameSeedSameResult) {
  ImageI32 truth;
  const ImageF points = blobImage(truth);
  const KMeansResult a = kmeansPoints(points, 7, 10, 0.001, 42);
  const KMeansResult b = kmeansPoints(points, 7, 10, 0.001, 42);
  ASSERT_EQ(a.centres.size(), b.centres.size());
  for (std::size_t c = 0; c < a.centres.size(); ++c) EXPECT_EQ(a.centres[c], b.centres[c]);
  EXPECT_EQ(a.assignment.data, b.assignment.data);
  EXPECT_EQ(a.iterations, b.iterations);
}

TEST(KMeans, APointListGivesTheClustersOfTheImageOfItsPoints) {
  // A warm start clusters the uncovered pixels as a list (kmeansPointList): the image's valid points in pixel order
  // must give the image's centres and assignment.
  ImageI32 truth;
  const ImageF points = blobImage(truth);
  std::vector<Eigen::Vector3f> list;
  std::vector<std::size_t> pixel;
  for (std::size_t k = 0; k < points.pixelCount(); ++k)
    if (truth.data[k] >= 0) {
      list.emplace_back(points.data[3 * k], points.data[3 * k + 1], points.data[3 * k + 2]);
      pixel.push_back(k);
    }
  for (const int k : {1, 3, 7}) {
    const KMeansResult image = kmeansPoints(points, k, 10, 0.001, 5);
    const KMeansPointsResult from_list = kmeansPointList(list, k, 10, 0.001, 5);
    ASSERT_EQ(from_list.centres.size(), image.centres.size()) << "k " << k;
    for (std::size_t c = 0; c < image.centres.size(); ++c) EXPECT_EQ(from_list.centres[c], image.centres[c]);
    ASSERT_EQ(from_list.assignment.size(), list.size());
    for (std::size_t i = 0; i < list.size(); ++i) EXPECT_EQ(from_list.assignment[i], image.assignment.data[pixel[i]]);
    EXPECT_EQ(from_list.iterations, image.iterations);
  }
  EXPECT_TRUE(kmeansPointList({}, 3, 10, 0.001, 5).centres.empty());
  EXPECT_THROW(kmeansPointList(list, 0, 10, 0.001, 5), InputError);
}

TEST(KMeans, FewerDistinctPointsThanK) {
  ImageF points(3, 2, 3, std::numeric_limits<float>::quiet_NaN());
  const float values[2][3] = {{0.f, 0.f, 1.f}, {0.5f, 0.f, 2.f}};
  for (int c = 0; c < 3; ++c) {
    points(0, 0, c) = values[0][c];
    points(1, 0, c) = values[0][c];  // duplicate
    points(2, 1, c) = values[1][c];
  }
  const KMeansResult r = kmeansPoints(points, 5, 10, 0.001, 3);
  EXPECT_EQ(r.centres.size(), 2u);
  EXPECT_EQ(r.assignment(0, 0), r.assignment(1, 0));
  EXPECT_NE(r.assignment(0, 0), r.assignment(2, 1));
  EXPECT_EQ(r.assignment(0, 1), -1);

  const KMeansResult none = kmeansPoints(ImageF(4, 4, 3, std::numeric_limits<float>::quiet_NaN()), 3, 10, 0.01, 1);
  EXPECT_TRUE(none.centres.empty());
  for (int a : none.assignment.data) EXPECT_EQ(a, -1);
}

TEST(KMeans, AssignToNearestCentre) {
  ImageF points(2, 1, 3);
  points(0, 0, 0) = 0.1f, points(0, 0, 1) = 0.f, points(0, 0, 2) = 1.f;
  points(1, 0, 0) = 0.9f, points(1, 0, 1) = 0.f, points(1, 0, 2) = 1.f;
  const std::vector<Eigen::Vector3f> centres = {{1.f, 0.f, 1.f}, {0.f, 0.f, 1.f}};
  const ImageI32 a = assignToNearestCentre(points, centres);
  EXPECT_EQ(a(0, 0), 1);
  EXPECT_EQ(a(1, 0), 0);
}

// The rule both backends share (nearest_centre.h): the lowest index wins a tie, and a single centre takes every point.
TEST(KMeans, NearestCentreIndexBreaksTiesTowardsTheLowestIndex) {
  const float centres[9] = {1.f, 0.f, 0.f, -1.f, 0.f, 0.f, 0.f, 0.f, 5.f};
  EXPECT_EQ(nearestCentreIndex(0.f, 0.f, 0.f, centres, 3), 0);  // equidistant from centres 0 and 1
  EXPECT_EQ(nearestCentreIndex(-0.1f, 0.f, 0.f, centres, 3), 1);
  EXPECT_EQ(nearestCentreIndex(0.f, 0.f, 4.f, centres, 3), 2);
  EXPECT_EQ(nearestCentreIndex(100.f, 100.f, 100.f, centres, 1), 0);
}

}  // namespace
}  // namespace mc_flow
