// Segment id persistence across pairs (ROS-free).
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "mc_flow/ros/segment_tracker.h"

using mc_flow::ImageF;
using mc_flow::ImageI32;
using mc_flow_ros::SegmentTracker;

namespace {

void fillRect(ImageI32& image, int x0, int y0, int x1, int y1, int value) {
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) image(x, y) = value;
}

ImageF uniformFlow(int w, int h, float u, float v) {
  ImageF flow(w, h, 2, 0.f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      flow(x, y, 0) = u;
      flow(x, y, 1) = v;
    }
  return flow;
}

}  // namespace

TEST(SegmentTracker, FirstPairGetsFreshIds) {
  SegmentTracker tracker;
  ImageI32 labels(40, 30, 1, 1);
  fillRect(labels, 5, 5, 15, 15, 2);
  const auto ids = tracker.update(labels, 2, ImageF());
  ASSERT_EQ(ids.size(), 2u);
  EXPECT_EQ(ids[0], 1u);
  EXPECT_EQ(ids[1], 2u);
  EXPECT_EQ(tracker.nextId(), 3u);
}

TEST(SegmentTracker, IdsFollowRegionsWhenSolverRenumbers) {
  SegmentTracker tracker;
  ImageI32 first(40, 30, 1, 1);  // background = label 1
  fillRect(first, 5, 5, 15, 15, 2);
  fillRect(first, 25, 10, 35, 25, 3);
  const auto ids1 = tracker.update(first, 3, ImageF());

  // Next pair: the same regions, numbered differently by the solver.
  ImageI32 second(40, 30, 1, 3);
  fillRect(second, 5, 5, 15, 15, 1);
  fillRect(second, 25, 10, 35, 25, 2);
  const auto ids2 = tracker.update(second, 3, ImageF());
  ASSERT_EQ(ids2.size(), 3u);
  EXPECT_EQ(ids2[2], ids1[0]);  // background
  EXPECT_EQ(ids2[0], ids1[1]);
  EXPECT_EQ(ids2[1], ids1[2]);
  EXPECT_EQ(tracker.nextId(), 4u);  // no new id was needed
}

TEST(SegmentTracker, OpticalFlowCarriesIdsToTheMovedRegion) {
  SegmentTracker tracker;
  ImageI32 first(60, 20, 1, 0);
  fillRect(first, 0, 0, 10, 20, 1);    // moves 20 px right
  fillRect(first, 40, 0, 60, 20, 2);   // static
  ImageF flow(60, 20, 2, 0.f);
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 10; ++x) flow(x, y, 0) = 20.f;
  const auto ids1 = tracker.update(first, 2, flow);

  // Without the flow, the moved region (now at 20..30) would overlap nothing of segment 1.
  ImageI32 second(60, 20, 1, 0);
  fillRect(second, 20, 0, 30, 20, 2);
  fillRect(second, 40, 0, 60, 20, 1);
  const auto ids2 = tracker.update(second, 2, ImageF());
  EXPECT_EQ(ids2[1], ids1[0]);
  EXPECT_EQ(ids2[0], ids1[1]);
}

TEST(SegmentTracker, NewRegionGetsNewIdAndOldIdsAreNotReused) {
  SegmentTracker tracker;
  ImageI32 first(40, 30, 1, 1);
  fillRect(first, 0, 0, 10, 10, 2);
  const auto ids1 = tracker.update(first, 2, ImageF());
  // Segment 2 disappears, a region appears elsewhere.
  ImageI32 second(40, 30, 1, 1);
  fillRect(second, 30, 20, 40, 30, 2);
  const auto ids2 = tracker.update(second, 2, ImageF());
  EXPECT_EQ(ids2[0], ids1[0]);
  EXPECT_NE(ids2[1], ids1[1]);
  EXPECT_EQ(ids2[1], 3u);
}

TEST(SegmentTracker, SplitKeepsIdForTheLargerOverlapOnly) {
  SegmentTracker tracker;
  ImageI32 first(40, 10, 1, 1);
  const auto ids1 = tracker.update(first, 1, ImageF());
  ImageI32 second(40, 10, 1, 1);
  fillRect(second, 30, 0, 40, 10, 2);  // a quarter splits off
  const auto ids2 = tracker.update(second, 2, ImageF());
  EXPECT_EQ(ids2[0], ids1[0]);
  EXPECT_NE(ids2[1], ids1[0]);
  const std::set<std::uint32_t> unique(ids2.begin(), ids2.end());
  EXPECT_EQ(unique.size(), ids2.size());
}

TEST(SegmentTracker, SmallOverlapDoesNotInheritAnId) {
  SegmentTracker::Options options;
  options.min_overlap = 0.5;
  SegmentTracker tracker(options);
  ImageI32 first(40, 10, 1, 0);
  fillRect(first, 0, 0, 10, 10, 1);
  tracker.update(first, 1, ImageF());
  ImageI32 second(40, 10, 1, 0);
  fillRect(second, 8, 0, 18, 10, 1);  // 20% overlap
  const auto ids = tracker.update(second, 1, ImageF());
  EXPECT_EQ(ids[0], 2u);
}

TEST(SegmentTracker, ResetAndSizeChangeStartFresh) {
  SegmentTracker tracker;
  ImageI32 labels(20, 10, 1, 1);
  const auto ids1 = tracker.update(labels, 1, ImageF());
  tracker.reset();
  const auto ids2 = tracker.update(labels, 1, ImageF());
  EXPECT_NE(ids2[0], ids1[0]);
  const auto ids3 = tracker.update(ImageI32(10, 5, 1, 1), 1, ImageF());
  EXPECT_NE(ids3[0], ids2[0]);
  const auto ids4 = tracker.update(ImageI32(10, 5, 1, 1), 1, uniformFlow(10, 5, 0.f, 0.f));
  EXPECT_EQ(ids4[0], ids3[0]);
}

TEST(SegmentTracker, ColoursAreStableAndDistinct) {
  EXPECT_EQ(mc_flow_ros::colourForId(0).r, mc_flow_ros::colourForId(0).g);  // grey for the outlier
  for (std::uint32_t a = 1; a <= 12; ++a) {
    const auto ca = mc_flow_ros::colourForId(a);
    const auto again = mc_flow_ros::colourForId(a);
    EXPECT_EQ(ca.r, again.r);
    EXPECT_EQ(ca.g, again.g);
    EXPECT_EQ(ca.b, again.b);
    for (std::uint32_t b = a + 1; b <= 12; ++b) {
      const auto cb = mc_flow_ros::colourForId(b);
      const double distance = std::sqrt(std::pow(ca.r - cb.r, 2) + std::pow(ca.g - cb.g, 2) + std::pow(ca.b - cb.b, 2));
      EXPECT_GT(distance, 25.0) << "ids " << a << " and " << b << " look alike";
    }
  }
}
