// Stream mode: carrying the previous pair's segments into the next frame 1, resampling them to a level,
// matching ids by overlap, and the solver's warm start and its fallbacks.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <set>

#include "mc_flow/core/error.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/core/warm_start.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "test_helpers.h"

namespace mc_flow {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// A previous result on a W x H grid: two segments (ids 7 left half, 9 right half) at depth 2 m, every point
// moving by `shift` pixels along x (and keeping its depth).
Result shiftedPrevious(int W, int H, int shift) {
  Result r;
  r.width = W;
  r.height = H;
  r.intrinsics = {100, 100, W / 2.0, H / 2.0};
  r.labels = ImageI32(W, H, 1, 0);
  r.optical_flow = ImageF(W, H, 2, 0.f);
  r.scene_flow = ImageF(W, H, 3, 0.f);
  r.moved_depth = ImageF(W, H, 1, 2.f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      r.labels(x, y) = x < W / 2 ? 7 : 9;
      r.optical_flow(x, y, 0) = float(shift);
    }
  Segment a, b;
  a.id = 7;
  b.id = 9;
  r.segments = {a, b};
  r.next_id = 10;
  return r;
}

ImageF planeDepth(int W, int H, float depth) { return ImageF(W, H, 1, depth); }

ImageF planePoints(int W, int H, float depth) {
  ImageF points(W, H, 3, 0.f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      points(x, y, 0) = (x - W / 2.f) / 100.f * depth;
      points(x, y, 1) = (y - H / 2.f) / 100.f * depth;
      points(x, y, 2) = depth;
    }
  return points;
}

// The solver's depth range (Config's defaults are wider than any value here).
constexpr float kMinDepth = 0.1f, kMaxDepth = 5.f;

TEST(WarmStart, CarriesIdsAlongTheFlowWhereTheDepthAgrees) {
  const int W = 40, H = 20;
  const Result previous = shiftedPrevious(W, H, 3);
  ImageF depth = planeDepth(W, H, 2.f);
  for (int x = 0; x < W; ++x) depth(x, 5) = 2.5f;  // row 5: another surface than the one that arrives
  depth(30, 10) = kNaN;                            // no depth
  depth(31, 10) = 0.f;                             // no depth either
  depth(32, 10) = 7.f;                             // beyond max_depth: not observed by the solver
  const ImageI32 carried = carrySegmentIds(previous, depth, kMinDepth, kMaxDepth, 0.05);
  // Columns 0..2 receive nothing (everything moved right); the boundary moves from 20 to 23.
  EXPECT_EQ(carried(1, 10), 0);
  EXPECT_EQ(carried(3, 10), 7);
  EXPECT_EQ(carried(22, 10), 7);
  EXPECT_EQ(carried(23, 10), 9);
  EXPECT_EQ(carried(39, 10), 9);
  EXPECT_EQ(carried(10, 5), 0) << "the observed depth is 0.5 m away from the carried point's";
  EXPECT_EQ(carried(30, 10), 0) << "no depth, no id";
  EXPECT_EQ(carried(31, 10), 0) << "no depth, no id";
  EXPECT_EQ(carried(32, 10), 0) << "a depth outside [min_depth, max_depth] is none";
  EXPECT_EQ(carried(33, 10), 9);
  // With a looser tolerance the row is carried too.
  EXPECT_EQ(carrySegmentIds(previous, depth, kMinDepth, kMaxDepth, 0.6)(10, 5), 7);
}

// Two points landing on one pixel: the nearer wins; of two equally near ones, the first in raster order (the splat runs
// on several threads; the result must be a serial splat's).
TEST(WarmStart, TheNearestPointWinsAPixelAndOfEquallyNearOnesTheFirst) {
  const int W = 8, H = 3;
  Result previous = shiftedPrevious(W, H, 0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) previous.labels(x, y) = 0;
  previous.labels(0, 1) = 7;  // lands on (2, 1)
  previous.labels(1, 1) = 9;  // lands on (2, 1) too
  previous.optical_flow(0, 1, 0) = 2.f;
  previous.optical_flow(1, 1, 0) = 1.f;
  const ImageF depth = planeDepth(W, H, 2.f);
  previous.moved_depth(0, 1) = 2.f;
  previous.moved_depth(1, 1) = 2.f;
  EXPECT_EQ(carrySegmentIds(previous, depth, kMinDepth, kMaxDepth, 0.2)(2, 1), 7) << "a tie: the first in raster order";
  previous.moved_depth(1, 1) = 1.9f;
  EXPECT_EQ(carrySegmentIds(previous, depth, kMinDepth, kMaxDepth, 0.2)(2, 1), 9) << "the nearer one";
  previous.moved_depth(1, 1) = std::numeric_limits<float>::infinity();
  EXPECT_EQ(carrySegmentIds(previous, depth, kMinDepth, kMaxDepth, 0.2)(2, 1), 7) << "an infinite depth lands nowhere";
}

TEST(WarmStart, ClosesOnePixelGapsOfASurfaceThatComesCloser) {
  const int W = 40, H = 20;
  Result previous = shiftedPrevious(W, H, 0);
  // Every second column of the previous frame is unlabelled: its points land nowhere.
  for (int y = 0; y < H; ++y)
    for (int x = 1; x < W; x += 2) previous.labels(x, y) = 0;
  const ImageI32 carried = carrySegmentIds(previous, planeDepth(W, H, 2.f), kMinDepth, kMaxDepth, 0.05);
  EXPECT_EQ(carried(11, 10), 7);
  EXPECT_EQ(carried(25, 10), 9);
}

TEST(WarmStart, RejectsAPreviousResultOfAnotherSize) {
  const Result previous = shiftedPrevious(40, 20, 0);
  EXPECT_THROW(carrySegmentIds(previous, planeDepth(20, 10, 2.f), kMinDepth, kMaxDepth, 0.05), InputError);
  EXPECT_THROW(carrySegmentIds(previous, ImageF(40, 20, 3, 2.f), kMinDepth, kMaxDepth, 0.05), InputError);
  Result empty;
  empty.width = 40;
  empty.height = 20;
  EXPECT_THROW(carrySegmentIds(empty, planeDepth(40, 20, 2.f), kMinDepth, kMaxDepth, 0.05), InputError);
  // The message names the image and its size.
  try {
    carrySegmentIds(empty, planeDepth(40, 20, 2.f), kMinDepth, kMaxDepth, 0.05);
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("id image has 0 values, expected 800"), std::string::npos) << e.what();
  }
}

TEST(WarmStart, LevelLabelsTakeTheMajorityOfTheirBlock) {
  ImageI32 ids(8, 4, 1, 0);
  // Block (0,0): three 5s and one 6 -> 5. Block (1,0): two 6s, two uncovered -> 6 (half). Block (2,0): one 6
  // -> uncovered. Block (3,0) has no depth at the level.
  ids(0, 0) = 5, ids(1, 0) = 5, ids(0, 1) = 5, ids(1, 1) = 6;
  ids(2, 0) = 6, ids(3, 1) = 6;
  ids(4, 0) = 6;
  ids(6, 0) = 5, ids(7, 0) = 5, ids(6, 1) = 5, ids(7, 1) = 5;
  ImageF level = planePoints(4, 2, 1.f);
  level(3, 0, 2) = kNaN;
  const CarriedLabels c = carriedLabelsAtLevel(ids, level, 2);
  ASSERT_EQ(c.ids.size(), 2u);
  EXPECT_EQ(c.ids[std::size_t(c.hard(0, 0))], 5);
  EXPECT_EQ(c.ids[std::size_t(c.hard(1, 0))], 6);
  EXPECT_EQ(c.hard(2, 0), -1);
  EXPECT_EQ(c.hard(3, 0), -1);
  EXPECT_EQ(c.valid, 7);
  EXPECT_EQ(c.covered, 2);
  EXPECT_THROW(carriedLabelsAtLevel(ids, level, 3), InputError);
  EXPECT_THROW(carriedLabelsAtLevel(ids, planePoints(8, 4, 1.f), 2), InputError);
}

TEST(WarmStart, MatchesIdsByOverlapEachIdOnce) {
  ImageI32 labels(10, 1, 1, 0), carried(10, 1, 1, 0);
  // Segment 1 covers 0..4, segment 2 covers 5..9, segment 3 is one pixel inside id 4's region.
  for (int x = 0; x < 10; ++x) labels(x, 0) = x < 5 ? 1 : 2;
  labels(9, 0) = 3;
  for (int x = 0; x < 10; ++x) carried(x, 0) = x < 6 ? 4 : 8;
  int next_id = 20;
  const std::vector<int> ids = matchSegmentIds(labels, 3, carried, 0.3, next_id);
  ASSERT_EQ(ids.size(), 3u);
  EXPECT_EQ(ids[0], 4);
  EXPECT_EQ(ids[1], 8);
  EXPECT_EQ(ids[2], 20) << "id 8 is taken by the larger overlap";
  EXPECT_EQ(next_id, 21);
  // Requiring the whole smaller region: segment 2 shares 3 of its 4 pixels with id 8 and gets a new id,
  // while segment 3 (one pixel, inside id 8's region) now takes id 8.
  next_id = 30;
  const std::vector<int> strict = matchSegmentIds(labels, 3, carried, 1.0, next_id);
  EXPECT_EQ(strict[0], 4);
  EXPECT_EQ(strict[1], 30);
  EXPECT_EQ(strict[2], 8);
  EXPECT_EQ(next_id, 31);
}

TEST(WarmStart, AnIdThatWentDormantComesBackWithItsRegion) {
  // Previous pair: one segment (id 1) and id 5 dormant (it had merged into 1), its region on the right half.
  // This pair: the right half is a segment of its own again: it takes id 5 back.
  Result previous;
  previous.next_id = 8;
  Segment bg;
  bg.id = 1;
  previous.segments = {bg};
  previous.dormant_ids = {{5, 3}};
  ImageI32 carried(10, 2, 1, 1), dormant(10, 2, 1, 0);
  for (int y = 0; y < 2; ++y)
    for (int x = 6; x < 10; ++x) dormant(x, y) = 5;
  Result r;
  r.width = 10;
  r.height = 2;
  r.labels = ImageI32(10, 2, 1, 1);
  for (int y = 0; y < 2; ++y)
    for (int x = 5; x < 10; ++x) r.labels(x, y) = 2;
  Segment a, b;
  a.id = 1;
  b.id = 2;
  r.segments = {a, b};
  Result kept = r;
  assignStreamIds(r, carried, dormant, previous, 0.3, 30);
  EXPECT_EQ(r.segments[0].id, 1);
  EXPECT_EQ(r.segments[1].id, 5);
  EXPECT_EQ(r.labels(9, 1), 5);
  ASSERT_EQ(r.revived_ids.size(), 1u);
  EXPECT_EQ(r.next_id, 8) << "no new id was used";
  EXPECT_TRUE(r.dormant_ids.empty()) << "5 is alive again";
  // Remembered for 3 pairs only: then the segment is new.
  assignStreamIds(kept, carried, dormant, previous, 0.3, 3);
  EXPECT_EQ(kept.segments[1].id, 5) << "age 3 is still within 3 pairs";
  Result older = previous;
  older.dormant_ids = {{5, 3}};
  Result fresh;
  fresh.width = 10;
  fresh.height = 2;
  fresh.labels = ImageI32(10, 2, 1, 1);
  fresh.segments = {a};
  assignStreamIds(fresh, carried, dormant, older, 0.3, 3);
  EXPECT_TRUE(fresh.dormant_ids.empty()) << "age 4 > 3: forgotten";
  // An id that merges now becomes dormant with its carried region.
  Result two = previous;
  two.dormant_ids.clear();
  Segment gone;
  gone.id = 4;
  two.segments = {bg, gone};
  ImageI32 carried_two(10, 2, 1, 1);
  carried_two(0, 0) = 4;
  carried_two(1, 0) = 4;
  Result merged;
  merged.width = 10;
  merged.height = 2;
  merged.labels = ImageI32(10, 2, 1, 1);
  merged.segments = {a};
  assignStreamIds(merged, carried_two, ImageI32(), two, 0.3, 30);
  ASSERT_EQ(merged.merged_ids.size(), 1u);
  EXPECT_EQ(merged.merged_ids[0], std::make_pair(4, 1));
  ASSERT_EQ(merged.dormant_ids.size(), 1u);
  EXPECT_EQ(merged.dormant_regions(1, 0), 4);
  EXPECT_EQ(merged.dormant_regions(5, 0), 0);
}

// ---------------------------------------------------------------- the solver in stream mode

SyntheticPair sequencePair(int variant, int first_frame, int width = 160, int height = 120) {
  SyntheticSceneOptions o;
  o.width = width;
  o.height = height;
  o.variant = variant;
  o.first_frame = first_frame;
  o.stream_events = true;
  return renderSyntheticPair(o);
}

double epe(const Result& r, const SyntheticPair& p) {
  return opticalFlowErrors(r.optical_flow, p.gt_optical_flow, &p.gt_occlusion).epe;
}

// The id most pixels of true part `part` carry.
int majorityId(const Result& r, const SyntheticPair& p, int part) {
  std::map<int, int> votes;
  for (std::size_t k = 0; k < r.labels.data.size(); ++k)
    if (p.gt_parts.data[k] == part && r.labels.data[k] > 0) ++votes[r.labels.data[k]];
  int best = 0, count = 0;
  for (const auto& [id, n] : votes)
    if (n > count) {
      best = id;
      count = n;
    }
  return best;
}

TEST(SolverStream, WarmStartKeepsIdsAndAccuracy) {
  Config config;
  Solver solver(config);
  const SyntheticPair p0 = sequencePair(0, 0), p1 = sequencePair(0, 1), p2 = sequencePair(0, 2);
  const Result r0 = solver.solve(p0.frame1, p0.frame2, p0.intrinsics);
  EXPECT_EQ(r0.start, StartKind::Cold);
  const Result r1 = solver.solve(p1.frame1, p1.frame2, p1.intrinsics, r0);
  const Result r2 = solver.solve(p2.frame1, p2.frame2, p2.intrinsics, r1);
  EXPECT_EQ(r1.start, StartKind::Warm) << r1.start_note;
  EXPECT_EQ(r2.start, StartKind::Warm) << r2.start_note;
  // Ids continue: the background and the two boxes keep theirs; new ids only come from next_id on.
  for (int part : {0, 1, 2}) {
    EXPECT_EQ(majorityId(r1, p1, part), majorityId(r0, p0, part)) << "part " << part;
    EXPECT_EQ(majorityId(r2, p2, part), majorityId(r1, p1, part)) << "part " << part;
  }
  std::set<int> known;
  for (const Segment& s : r0.segments) known.insert(s.id);
  for (const Segment& s : r1.segments) EXPECT_TRUE(known.count(s.id) || s.id >= r0.next_id) << "id " << s.id;
  EXPECT_GE(r1.next_id, r0.next_id);
  EXPECT_GE(r2.next_id, r1.next_id);
  // The ids in the label image are the segments' ids.
  std::set<int> segment_ids;
  for (const Segment& s : r2.segments) segment_ids.insert(s.id);
  for (const int id : r2.labels.data) EXPECT_TRUE(id == 0 || segment_ids.count(id)) << "label " << id;
  // As accurate as a cold solve of the same pair (measured at 160x120: cold 0.07-0.08 px, warm 0.05-0.06 px).
  Solver cold_solver(config);
  const Result c1 = cold_solver.solve(p1.frame1, p1.frame2, p1.intrinsics);
  const Result c2 = cold_solver.solve(p2.frame1, p2.frame2, p2.intrinsics);
  EXPECT_LE(epe(r1, p1), 1.2 * epe(c1, p1) + 0.01);
  EXPECT_LE(epe(r2, p2), 1.2 * epe(c2, p2) + 0.01);
  // warm_outer_iterations outer iterations, and one more after each that split labels.
  for (const Result* r : {&r1, &r2}) {
    int expected = config.warm_outer_iterations;
    for (std::size_t k = 0; k < r->iterations.size(); ++k)
      if (int(k) + 1 >= config.warm_outer_iterations && r->iterations[k].split > 0) expected = int(k) + 2;
    EXPECT_EQ(int(r->iterations.size()), std::min(expected, config.outer_iterations));
  }
}

// Synthetic variant 0 at 320x240: around frame 6 the parts' velocities pass through zero together, so for a pair or two
// they move like the background. The switching cost (warm_switch_cost) keeps the segments the previous pairs found
// against the label price; but where one motion explains a part and the background within the noise
// (merge_refit_tolerance), they merge, switching cost or not: one rigid motion, one segment, as a static scene must
// stay one segment in a stream (the decision of the issue that introduced the merge test; docs/decisions). Measured at
// 320x240: with the merge test off every part keeps its id in pairs 4-7; with it the resting parts merge; without the
// switching cost either way they merge.
TEST(SolverStream, PartsThatMoveAlikeForAMomentKeepTheirSegments) {
  // Frames 4-7 of variant 0: parts at the turn of their motions move alike for a moment. The switching cost keeps
  // them apart in the label-count update; in the merge test, the memory of how they moved a pair ago and the stricter
  // tolerance of two carried segments do.
  auto idChanges = [](const Config& config) {
    Solver solver(config);
    Result previous;
    std::map<int, int> previous_ids;
    int changes = 0;
    for (int frame = 4; frame <= 7; ++frame) {
      const SyntheticPair p = sequencePair(0, frame, 320, 240);
      Result r = frame == 4 ? solver.solve(p.frame1, p.frame2, p.intrinsics)
                            : solver.solve(p.frame1, p.frame2, p.intrinsics, previous);
      for (const int part : {0, 1, 2, 3}) {
        const int id = majorityId(r, p, part);
        if (frame > 4 && id != previous_ids[part]) ++changes;
        previous_ids[part] = id;
      }
      previous = std::move(r);
    }
    return changes;
  };
  const Config defaults;
  EXPECT_EQ(idChanges(defaults), 0);
  Config no_merge_test = defaults;
  no_merge_test.merge_refit_tolerance = 0;
  EXPECT_EQ(idChanges(no_merge_test), 0);
  Config no_switch_cost = no_merge_test;
  no_switch_cost.warm_switch_cost = 0;
  EXPECT_GT(idChanges(no_switch_cost), 0);  // without the switching cost the parts merge
  // Without the memory, and with the tolerance of the widest segment for carried pairs, one motion explains them for a
  // moment, and they merge.
  Config no_memory = defaults;
  no_memory.merge_memory_displacement = 0;
  no_memory.merge_refit_tolerance_parts = no_memory.merge_refit_tolerance;
  EXPECT_GT(idChanges(no_memory), 0);
}

TEST(SolverStream, ColdStartsKeepIdsByOverlap) {
  Config config;
  config.warm_start = false;
  Solver solver(config);
  const SyntheticPair p0 = sequencePair(0, 0), p1 = sequencePair(0, 1);
  const Result r0 = solver.solve(p0.frame1, p0.frame2, p0.intrinsics);
  const Result r1 = solver.solve(p1.frame1, p1.frame2, p1.intrinsics, r0);
  EXPECT_EQ(r1.start, StartKind::Cold);
  EXPECT_TRUE(r1.start_note.empty());
  for (int part : {0, 1, 2}) EXPECT_EQ(majorityId(r1, p1, part), majorityId(r0, p0, part)) << "part " << part;
  EXPECT_GE(r1.next_id, r0.next_id);
}

TEST(SolverStream, FallsBackToColdWhenThePreviousSegmentsDoNotFit) {
  // A scene change: the previous pair saw two planes, this one a room; almost no carried point meets a
  // surface at its depth.
  Config config;
  Solver solver(config);
  const test::TwoPlaneScene planes =
      test::renderTwoPlaneScene(160, 120, se3Exp((Vector6d() << 0.01, 0, 0, 0, 0.01, 0).finished()));
  const Result previous = solver.solve(planes.frame1, planes.frame2, planes.K);
  const SyntheticPair p1 = sequencePair(0, 1);
  const Result r = solver.solve(p1.frame1, p1.frame2, p1.intrinsics, previous);
  EXPECT_EQ(r.start, StartKind::ColdFallback);
  EXPECT_NE(r.start_note.find("warm_min_coverage"), std::string::npos) << r.start_note;
  Solver fresh(config);
  const Result cold = fresh.solve(p1.frame1, p1.frame2, p1.intrinsics);
  EXPECT_DOUBLE_EQ(r.energy, cold.energy) << "the fallback is the cold solve";
  EXPECT_GE(r.next_id, previous.next_id) << "ids are not reused";
}

TEST(SolverStream, AWarmStartWithNothingCarriedStartsFromKMeansAlone) {
  // warm_min_coverage = 0 admits a warm start that carries no segment (here: the previous result's ids all erased):
  // every label comes from the K-means of the uncovered pixels, from a zero motion.
  Config config;
  config.warm_min_coverage = 0;
  Solver solver(config);
  const SyntheticPair p0 = sequencePair(0, 0), p1 = sequencePair(0, 1);
  Result previous = solver.solve(p0.frame1, p0.frame2, p0.intrinsics);
  std::fill(previous.labels.data.begin(), previous.labels.data.end(), 0);
  previous.device_outputs = 0;  // edited in place: a CUDA backend must not read its own copy of the ids
  const Result r = solver.solve(p1.frame1, p1.frame2, p1.intrinsics, previous);
  EXPECT_EQ(r.start, StartKind::Warm) << r.start_note;
  EXPECT_GE(r.segments.size(), 1u);
  for (const Segment& segment : r.segments) EXPECT_GE(segment.id, previous.next_id) << "no id was carried";
}

TEST(SolverStream, DetectsAJumpInTheSequence) {
  // The camera jumps: frame 2 is where a camera moving six times as fast would be, while the carried motions
  // are those of one frame. The warm result explains the pair much worse than the previous pair was
  // explained (measured: 1.56 against 0.52 per pixel), and the cold solve that follows does better (0.73).
  Config config;
  Solver solver(config);
  const SyntheticPair p0 = sequencePair(2, 0);
  const Result r0 = solver.solve(p0.frame1, p0.frame2, p0.intrinsics);
  SyntheticSceneOptions fast;
  fast.width = 160;
  fast.height = 120;
  fast.variant = 2;
  fast.stream_events = true;
  fast.motion_scale = 6;
  fast.first_frame = 1;
  const SyntheticPair jump = renderSyntheticPair(fast);
  const SyntheticPair p1 = sequencePair(2, 1);
  const Result r = solver.solve(p1.frame1, jump.frame2, p1.intrinsics, r0);
  EXPECT_EQ(r.start, StartKind::ColdFallback);
  EXPECT_NE(r.start_note.find("warm_max_energy_ratio"), std::string::npos) << r.start_note;
  Solver fresh(config);
  const Result cold = fresh.solve(p1.frame1, jump.frame2, p1.intrinsics);
  EXPECT_DOUBLE_EQ(r.energy, cold.energy) << "the fallback is the cold solve";
  // Without the check the stale prior would have been kept.
  config.warm_max_energy_ratio = 100;
  Solver trusting(config);
  const Result kept =
      trusting.solve(p1.frame1, jump.frame2, p1.intrinsics, trusting.solve(p0.frame1, p0.frame2, p0.intrinsics));
  EXPECT_EQ(kept.start, StartKind::Warm);
  EXPECT_GT(kept.energy, 1.5 * cold.energy);
}

}  // namespace
}  // namespace mc_flow
