// End-to-end tests of the solver on the project's synthetic scenes (known motions, occlusions, parts).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <map>

#include "mc_flow/core/error.h"
#include "mc_flow/testing/metrics.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/testing/synthetic_scene.h"
#include "test_helpers.h"

using namespace mc_flow;

namespace {

struct PartError {
  double mean_epe = 0;
  int pixels = 0;
};

std::map<int, PartError> perPartEpe(const Result& r, const SyntheticPair& pair) {
  std::map<int, PartError> out;
  for (int y = 0; y < r.height; ++y)
    for (int x = 0; x < r.width; ++x) {
      const float u = r.optical_flow(x, y, 0), v = r.optical_flow(x, y, 1);
      const float gu = pair.gt_optical_flow(x, y, 0), gv = pair.gt_optical_flow(x, y, 1);
      if (!std::isfinite(u) || !std::isfinite(gu) || pair.gt_occlusion(x, y)) continue;
      PartError& e = out[pair.gt_parts(x, y)];
      e.mean_epe += std::hypot(u - gu, v - gv);
      ++e.pixels;
    }
  for (auto& kv : out) kv.second.mean_epe /= std::max(1, kv.second.pixels);
  return out;
}

class SolverOnSyntheticScenes : public ::testing::TestWithParam<std::tuple<int, Regularizer>> {};

}  // namespace

// Thresholds: the synthetic pairs move parts by 2-15 px; a solver with a broken motion step leaves EPEs of
// several pixels, a broken label step mixes parts (agreement < 0.85, part EPEs > 1 px). Measured values
// are in docs/ACCURACY.md (about 0.1 px overall, below 1.3 px on every part).
TEST_P(SolverOnSyntheticScenes, RecoversFlowSegmentsAndOcclusions) {
  const int variant = std::get<0>(GetParam());
  Config config;
  config.regularizer = std::get<1>(GetParam());
  config.backend = Backend::Cpu;
  SyntheticSceneOptions options;
  options.variant = variant;
  const SyntheticPair pair = renderSyntheticPair(options);
  Solver solver(config);
  const Result r = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);

  const FlowErrors fe = opticalFlowErrors(r.optical_flow, pair.gt_optical_flow, &pair.gt_occlusion);
  EXPECT_LT(fe.epe, 0.4) << "variant " << variant;
  EXPECT_LT(sceneFlowEpe(r.scene_flow, pair.gt_scene_flow, &pair.gt_occlusion), 0.005);
  EXPECT_GT(segmentationAgreement(r.labels, pair.gt_parts), 0.88);
  EXPECT_GT(maskAgreement(r.occlusion, pair.gt_occlusion, nullptr), 0.95);
  EXPECT_GE(r.segments.size(), 2u);
  EXPECT_LE(r.segments.size(), 10u);
  for (const auto& kv : perPartEpe(r, pair)) {
    if (kv.second.pixels < 800) continue;  // parts this small can merge with a neighbour of similar motion
    EXPECT_LT(kv.second.mean_epe, 1.5) << "part " << kv.first << " (" << kv.second.pixels << " px)";
  }
  // Rigid parts: the segment covering most of a part moves it like the truth. The arm's links are skipped:
  // K-means does not separate them, so one segment takes a blend of their motions (see README).
  for (const SyntheticPart& part : pair.parts) {
    if (part.name.find("arm") != std::string::npos) continue;
    std::map<int, int> votes;
    for (int y = 0; y < r.height; ++y)
      for (int x = 0; x < r.width; ++x)
        if (pair.gt_parts(x, y) == part.id && r.labels(x, y) > 0) ++votes[r.labels(x, y)];
    auto best = std::max_element(votes.begin(), votes.end(), [](auto& a, auto& b) { return a.second < b.second; });
    ASSERT_NE(best, votes.end()) << "part " << part.name << " has no segment";
    const Eigen::Matrix4d D = se3Exp(r.segments[std::size_t(best->first - 1)].twist).inverse() * se3Exp(part.twist);
    const double rotation_error_deg = Eigen::AngleAxisd(Eigen::Matrix3d(D.topLeftCorner<3, 3>())).angle() * 180 / M_PI;
    std::printf("variant %d %s: rotation error %.2f deg of %.2f deg\n", variant, part.name.c_str(), rotation_error_deg,
                part.twist.tail<3>().norm() * 180 / M_PI);
    EXPECT_LT(rotation_error_deg, 2.0) << "part " << part.name << " (true rotation "
                                       << part.twist.tail<3>().norm() * 180 / M_PI << " deg)";
  }
  // Table 1 metric: warping with the estimate explains frame 2 better than zero flow.
  const ResidualRmse zero = warpResidualRmse(pair.frame1, pair.frame2, pair.intrinsics, nullptr, &r.occlusion);
  const ResidualRmse est = warpResidualRmse(pair.frame1, pair.frame2, pair.intrinsics, &r.scene_flow, &r.occlusion);
  EXPECT_LT(est.photometric, 0.7 * zero.photometric);
}

INSTANTIATE_TEST_SUITE_P(AllVariants, SolverOnSyntheticScenes,
                         ::testing::Combine(::testing::Range(0, 3),
                                            ::testing::Values(Regularizer::Quadratic, Regularizer::TotalVariation)));

TEST(Solver, OutputsAreConsistent) {
  SyntheticSceneOptions options;
  options.width = 160;
  options.height = 120;
  const SyntheticPair pair = renderSyntheticPair(options);
  Config config;
  config.backend = Backend::Cpu;
  Solver solver(config);
  const Result r = solver.solve(pair.frame1, pair.frame2, pair.intrinsics);
  ASSERT_EQ(r.width, 160);
  ASSERT_EQ(r.height, 120);
  ASSERT_EQ(r.soft_labels.count, int(r.segments.size()) + 1);
  for (int y = 0; y < r.height; ++y)
    for (int x = 0; x < r.width; ++x) {
      float sum = 0, best = -1;
      int arg = -1;
      for (int i = 0; i < r.soft_labels.count; ++i) {
        const float v = r.soft_labels.at(i, x, y);
        EXPECT_GE(v, -1e-6f);
        sum += v;
        if (v > best) best = v, arg = i;
      }
      EXPECT_NEAR(sum, 1.f, 1e-4f);
      const bool valid = isValidDepth(pair.frame1.depth(x, y));
      EXPECT_EQ(std::isfinite(r.scene_flow(x, y, 0)), valid);
      EXPECT_EQ(std::isfinite(r.optical_flow(x, y, 1)), valid);
      if (!valid) {
        EXPECT_EQ(r.labels(x, y), 0);
        EXPECT_FLOAT_EQ(r.soft_labels.at(r.soft_labels.outlier(), x, y), 1.f);
      } else {
        EXPECT_EQ(r.labels(x, y), arg == r.soft_labels.outlier() ? 0 : arg + 1);
      }
    }
  for (const Segment& s : r.segments) EXPECT_TRUE(s.transform.isApprox(se3Exp(s.twist)));
  EXPECT_GT(r.timings.total, 0.0);
  EXPECT_FALSE(r.iterations.empty());
  EXPECT_EQ(r.backend, "cpu");
  EXPECT_EQ(r.backend_kind, Backend::Cpu);
  // The motion step's statistics per level reach the result: coarse to fine, ending at the processing level,
  // iterations adding up to the iteration's total, each with the reason its loop stopped.
  for (const OuterIterationStats& it : r.iterations) {
    ASSERT_FALSE(it.motion_levels.empty());
    EXPECT_EQ(it.motion_levels.back().level, config.processing_level);
    int sum = 0;
    for (std::size_t k = 0; k < it.motion_levels.size(); ++k) {
      const MotionLevelStats& m = it.motion_levels[k];
      if (k > 0) EXPECT_EQ(m.level, it.motion_levels[k - 1].level - 1);
      EXPECT_NE(m.stop, MotionStop::NoLabels);
      EXPECT_GT(m.iterations, 0);
      sum += m.iterations;
    }
    EXPECT_EQ(sum, it.motion_iterations);
  }
}

TEST(Solver, StaticSceneGivesZeroMotion) {
  SyntheticSceneOptions options;
  options.width = 160;
  options.height = 120;
  const SyntheticPair pair = renderSyntheticPair(options);
  Solver solver(Config{});
  const Result r = solver.solve(pair.frame1, pair.frame1, pair.intrinsics);
  for (const Segment& s : r.segments) {
    EXPECT_LT(s.twist.head<3>().norm(), 1e-3) << s.twist.transpose();
    EXPECT_LT(s.twist.tail<3>().norm(), 1e-3) << s.twist.transpose();
  }
  const FlowErrors fe = opticalFlowErrors(r.optical_flow, pair.gt_optical_flow, nullptr);
  (void)fe;
  double max_flow = 0;
  for (int i = 0; i < r.width * r.height; ++i)
    if (std::isfinite(r.optical_flow.data[std::size_t(i) * 2]))
      max_flow = std::max(max_flow, double(std::hypot(r.optical_flow.data[std::size_t(i) * 2], r.optical_flow.data[std::size_t(i) * 2 + 1])));
  EXPECT_LT(max_flow, 0.05);
  EXPECT_EQ(r.segments.size(), 1u) << "identical frames: every label has the same (zero) motion and merges";
}

TEST(Solver, LabelStepPlacesAMotionBoundaryThatDepthDoesNotShow) {
  // A flat wall whose left part slides: K-means clusters straddle the boundary, so without the label step
  // the straddling clusters keep a compromise motion. Guards the end-to-end thresholds against a label
  // step that silently does nothing.
  Vector6d xi;
  xi << 0.04, 0.01, 0.0, 0.0, 0.0, 0.01;
  const test::SplitPlaneScene s = test::renderSplitPlaneScene(320, 240, se3Exp(xi), 0.17);
  Config full;
  Config starved;
  starved.label_iterations = 1;
  starved.label_iterations_final = 1;
  starved.outer_iterations = 1;
  const Result a = Solver(full).solve(s.frame1, s.frame2, s.K);
  const Result b = Solver(starved).solve(s.frame1, s.frame2, s.K);
  const FlowErrors ea = opticalFlowErrors(a.optical_flow, s.gt_optical_flow, &a.occlusion);
  const FlowErrors eb = opticalFlowErrors(b.optical_flow, s.gt_optical_flow, &b.occlusion);
  EXPECT_LT(ea.epe, 0.5) << "full solver";
  EXPECT_LT(ea.epe, 0.5 * eb.epe) << "full " << ea.epe << " px, starved label step " << eb.epe << " px";
}

TEST(Solver, RejectsBadInput) {
  SyntheticSceneOptions options;
  options.width = 80;
  options.height = 60;
  const SyntheticPair pair = renderSyntheticPair(options);
  Solver solver(Config{});
  // size mismatch between the frames
  SyntheticSceneOptions other = options;
  other.width = 64;
  other.height = 48;
  const SyntheticPair small = renderSyntheticPair(other);
  try {
    solver.solve(pair.frame1, small.frame2, pair.intrinsics);
    FAIL() << "size mismatch accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("80x60"), std::string::npos) << e.what();
  }
  // all-invalid depth
  RgbdFrame empty = pair.frame1;
  std::fill(empty.depth.data.begin(), empty.depth.data.end(), 0.f);
  EXPECT_THROW(solver.solve(empty, pair.frame2, pair.intrinsics), InputError);
  // depth only beyond max_depth
  RgbdFrame far = pair.frame1;
  std::fill(far.depth.data.begin(), far.depth.data.end(), 50.f);
  EXPECT_THROW(solver.solve(far, pair.frame2, pair.intrinsics), InputError);
  // NaN intensity
  RgbdFrame nan = pair.frame1;
  nan.intensity(3, 3) = std::nanf("");
  EXPECT_THROW(solver.solve(nan, pair.frame2, pair.intrinsics), InputError);
  // zero intrinsics
  Intrinsics zero = pair.intrinsics;
  zero.fx = 0;
  try {
    solver.solve(pair.frame1, pair.frame2, zero);
    FAIL() << "fx = 0 accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("fx"), std::string::npos) << e.what();
  }
  // NaN depth is a valid "no measurement"
  RgbdFrame nan_depth = pair.frame1;
  nan_depth.depth(5, 5) = std::nanf("");
  EXPECT_NO_THROW(solver.solve(nan_depth, pair.frame2, pair.intrinsics));
}

TEST(Solver, RejectsBadConfig) {
  Config c;
  c.initial_labels = 0;
  EXPECT_THROW(Solver{c}, ConfigError);
  Config tooDeep;
  tooDeep.processing_level = 6;
  SyntheticSceneOptions options;
  options.width = 80;
  options.height = 60;
  const SyntheticPair pair = renderSyntheticPair(options);
  EXPECT_THROW(Solver(tooDeep).solve(pair.frame1, pair.frame2, pair.intrinsics), ConfigError);
}

TEST(Solver, DeterministicForAGivenSeed) {
  SyntheticSceneOptions options;
  options.width = 160;
  options.height = 120;
  const SyntheticPair pair = renderSyntheticPair(options);
  Config config;
  config.threads = 2;  // several threads: the parallel reductions must not depend on scheduling
  const Result a = Solver(config).solve(pair.frame1, pair.frame2, pair.intrinsics);
  const Result b = Solver(config).solve(pair.frame1, pair.frame2, pair.intrinsics);
  ASSERT_EQ(a.segments.size(), b.segments.size());
  for (std::size_t i = 0; i < a.segments.size(); ++i) EXPECT_EQ(a.segments[i].twist, b.segments[i].twist);
  EXPECT_EQ(a.soft_labels.data, b.soft_labels.data);
}
