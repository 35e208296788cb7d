// CUDA motion step (cuda/motion_estimation.cu) against the CPU reference (CpuMotionAccumulator in
// src/core/motion_estimation.cpp).
//
// Tolerances. The GPU reproduces the CPU's warps, samples and residuals operation for operation, so which
// pixels count (in view, depth jump, active labels) must agree exactly: `pixels` is compared for equality.
// The Jacobian products may be contracted into FMAs (a few float ulps per pixel) and the double sums run
// in another order, so H, g and the costs agree to a relative kRelativeTolerance = 1e-6 (measured against
// the largest entry of the quantity: entries near zero come from cancelling sums). The observed differences
// are recorded as test properties.
#include <gtest/gtest.h>

#include "skip_without_gpu.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/core/motion_estimation.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "coupled_labels.h"

namespace mc_flow {

namespace {

constexpr double kRelativeTolerance = 1e-6;
constexpr double kTwistTolerance = 1e-5;  // end to end, after all IRLS iterations of all levels

enum class LabelKind { OneHot, Blended };

struct Scene {
  SyntheticPair pair;
  Pyramid p1, p2;
};

Scene makeScene(int width, int height, int levels, int variant = 0) {
  SyntheticSceneOptions options;
  options.width = width;
  options.height = height;
  options.variant = variant;
  Scene s;
  s.pair = renderSyntheticPair(options);
  Config config;
  s.p1 = buildPyramid(s.pair.frame1, s.pair.intrinsics, levels, config);
  s.p2 = buildPyramid(s.pair.frame2, s.pair.intrinsics, levels, config);
  return s;
}

// Motion label of a ground-truth part (the background and each part spread over the labels).
int labelOfPart(int part, int motion_labels) { return part % motion_labels; }

// Soft labels at full resolution. OneHot: each pixel's part label, with 10% of the pixels handing some mass
// to the outlier plane and 3% outlier-only. Blended: each pixel spreads over 1-3 labels with random weights,
// some below min_label_weight, plus random outlier mass (sometimes all of it).
SoftLabels makeLabels(const SyntheticPair& pair, int motion_labels, LabelKind kind, unsigned seed) {
  const int W = pair.frame1.width(), H = pair.frame1.height();
  SoftLabels u(W, H, motion_labels + 1, 0.f);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const int own = labelOfPart(pair.gt_parts(x, y), motion_labels);
      const float draw = unit(rng);
      float outlier = draw < 0.03f ? 1.f : draw < 0.13f ? 0.5f * unit(rng) : 0.f;
      std::vector<float> values(std::size_t(motion_labels), 0.f);
      if (kind == LabelKind::OneHot) {
        values[std::size_t(own)] = 1.f;
      } else {
        values[std::size_t(own)] = 0.2f + unit(rng);
        const int extra = motion_labels > 1 ? int(rng() % 3u) : 0;  // 0, 1 or 2 more labels
        for (int k = 0; k < extra; ++k) {
          const int other = int(rng() % unsigned(motion_labels));
          // Some shares far below min_label_weight (0.01), some around it, most well above.
          const float kindDraw = unit(rng);
          values[std::size_t(other)] += kindDraw < 0.2f ? 0.002f * unit(rng) : kindDraw < 0.3f ? 0.012f : unit(rng);
        }
      }
      float sum = 0.f;
      for (float v : values) sum += v;
      for (int i = 0; i < motion_labels; ++i) u.at(i, x, y) = (1.f - outlier) * values[std::size_t(i)] / sum;
      u.at(motion_labels, x, y) = outlier;
    }
  return u;
}

ImageU8 makeOcclusion(const SyntheticPair& pair, unsigned seed) {
  ImageU8 mask = pair.gt_occlusion;
  std::mt19937 rng(seed);
  for (auto& m : mask.data)
    if (rng() % 20u == 0u) m = 255;
  return mask;
}

// Twists per label: zero, the ground truth of the label's first part, or the truth plus a large
// perturbation that pushes many pixels out of view.
enum class TwistKind { Zero, Truth, OutOfView };

std::vector<Vector6d> makeTwists(const SyntheticPair& pair, int motion_labels, TwistKind kind, unsigned seed) {
  std::vector<Vector6d> twists(std::size_t(motion_labels), Vector6d::Zero());
  if (kind == TwistKind::Zero) return twists;
  for (int i = 0; i < motion_labels; ++i)
    for (const SyntheticPart& part : pair.parts)
      if (labelOfPart(part.id, motion_labels) == i) {
        twists[std::size_t(i)] = part.twist;
        break;
      }
  if (kind == TwistKind::OutOfView) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> pm(-1.0, 1.0);
    for (Vector6d& xi : twists) {
      xi(0) += 0.4 * pm(rng);  // [m]: tens of pixels at the scene's depths
      xi(1) += 0.3 * pm(rng);
      xi(2) += 0.1 * pm(rng);
      xi.tail<3>() += 0.05 * Eigen::Vector3d(pm(rng), pm(rng), pm(rng));
    }
  }
  return twists;
}

double maxAbs(const Eigen::MatrixXd& m) { return m.size() ? m.cwiseAbs().maxCoeff() : 0.0; }

// Largest difference relative to the largest reference entry (0 when both are all zero).
double relativeDifference(const Eigen::MatrixXd& gpu, const Eigen::MatrixXd& cpu) {
  const double scale = maxAbs(cpu);
  const double diff = maxAbs(gpu - cpu);
  return scale > 0 ? diff / scale : diff;
}

struct Comparison {
  double h = 0, g = 0, label_cost = 0, label_pixels = 0, cost = 0;
};

Comparison compareSums(const MotionNormalEquations& gpu, const MotionNormalEquations& cpu, const std::string& what) {
  Comparison c;
  EXPECT_EQ(gpu.H.rows(), cpu.H.rows()) << what;
  EXPECT_EQ(gpu.g.size(), cpu.g.size()) << what;
  if (gpu.H.rows() != cpu.H.rows() || gpu.g.size() != cpu.g.size()) return c;
  EXPECT_EQ(gpu.pixels, cpu.pixels) << what;
  c.h = relativeDifference(gpu.H, cpu.H);
  c.g = relativeDifference(gpu.g, cpu.g);
  c.label_cost = relativeDifference(gpu.label_cost, cpu.label_cost);
  c.label_pixels = relativeDifference(gpu.label_pixels, cpu.label_pixels);
  c.cost = std::abs(gpu.cost - cpu.cost) / std::max(std::abs(cpu.cost), 1e-300);
  EXPECT_LE(c.h, kRelativeTolerance) << what;
  EXPECT_LE(c.g, kRelativeTolerance) << what;
  EXPECT_LE(c.label_cost, kRelativeTolerance) << what;
  EXPECT_LE(c.label_pixels, kRelativeTolerance) << what;
  EXPECT_LE(c.cost, kRelativeTolerance) << what;
  EXPECT_TRUE(gpu.H.allFinite() && gpu.g.allFinite()) << what;
  return c;
}

// Pixels the motion step may use: finite point, not occluded, motion mass >= 0.05, one label above
// min_label_weight (the CPU's selection, restated).
int eligiblePixels(const PyramidLevel& f1, const SoftLabels& u, const ImageU8* occluded, const Config& config) {
  int count = 0;
  const int n = u.count - 1;
  for (int y = 0; y < u.height; ++y)
    for (int x = 0; x < u.width; ++x) {
      if (!std::isfinite(f1.points(x, y, 2)) || (occluded && (*occluded)(x, y))) continue;
      float mass = 0.f;
      for (int i = 0; i < n; ++i) mass += u.at(i, x, y);
      if (mass < 0.05f) continue;
      bool any = false;
      for (int i = 0; i < n; ++i) any = any || u.at(i, x, y) / mass >= float(config.min_label_weight);
      count += any ? 1 : 0;
    }
  return count;
}

// Runs both accumulators on level `level` of the scene for every twist kind and compares; returns the
// largest differences seen.
Comparison compareOnScene(const Scene& s, int level, int motion_labels, LabelKind label_kind, bool with_occlusion) {
  const PyramidLevel& f1 = s.p1[level];
  const PyramidLevel& f2 = s.p2[level];
  SoftLabels labels = makeLabels(s.pair, motion_labels, label_kind, 7u + unsigned(motion_labels));
  for (int l = 1; l <= level; ++l) labels = downsampleLabels(labels, s.p1[l].points.width, s.p1[l].points.height);
  EXPECT_EQ(labels.width, f1.points.width);
  EXPECT_EQ(labels.height, f1.points.height);
  ImageU8 occlusion;
  if (with_occlusion) {
    occlusion = ImageU8(f1.points.width, f1.points.height, 1, 0);
    const ImageU8 full = makeOcclusion(s.pair, 3u);
    const int step = 1 << level;
    for (int y = 0; y < occlusion.height; ++y)
      for (int x = 0; x < occlusion.width; ++x)
        occlusion(x, y) = full(std::min(x * step, full.width - 1), std::min(y * step, full.height - 1));
  }
  Config config;
  auto cpu = makeCpuMotionAccumulator();
  auto gpu = makeCudaMotionAccumulator();
  EXPECT_EQ(gpu->name(), "cuda");
  cpu->setLevel(f1, f2, labels, with_occlusion ? &occlusion : nullptr, config);
  gpu->setLevel(f1, f2, labels, with_occlusion ? &occlusion : nullptr, config);
  Comparison worst;
  for (TwistKind kind : {TwistKind::Zero, TwistKind::Truth, TwistKind::OutOfView}) {
    const std::vector<Vector6d> twists = makeTwists(s.pair, motion_labels, kind, 11u);
    MotionNormalEquations a, b;
    cpu->accumulate(twists, a);
    gpu->accumulate(twists, b);
    const std::string what = std::to_string(f1.points.width) + "x" + std::to_string(f1.points.height) + ", " +
                             std::to_string(motion_labels) + " labels, " +
                             (label_kind == LabelKind::OneHot ? "one-hot" : "blended") + ", twist kind " +
                             std::to_string(int(kind));
    // The scenario must exercise what it claims: at zero motion every eligible pixel stays in view; the
    // perturbed twists push some out of view (they then add cost but no residuals).
    const int eligible = eligiblePixels(f1, labels, with_occlusion ? &occlusion : nullptr, config);
    EXPECT_GT(a.pixels, 0) << what;
    if (kind == TwistKind::Zero) EXPECT_EQ(a.pixels, eligible) << what;
    if (kind == TwistKind::OutOfView) EXPECT_LT(a.pixels, eligible) << what;
    if (label_kind == LabelKind::Blended && motion_labels > 1) {
      // Blended pixels couple labels: some off-diagonal block is non-zero.
      Eigen::MatrixXd off = a.H;
      for (int i = 0; i < motion_labels; ++i) off.block<6, 6>(6 * i, 6 * i).setZero();
      EXPECT_GT(maxAbs(off), 0.0) << what;
    }
    const Comparison c = compareSums(b, a, what);
    worst.h = std::max(worst.h, c.h);
    worst.g = std::max(worst.g, c.g);
    worst.label_cost = std::max(worst.label_cost, c.label_cost);
    worst.label_pixels = std::max(worst.label_pixels, c.label_pixels);
    worst.cost = std::max(worst.cost, c.cost);
  }
  return worst;
}

void record(const Comparison& c) {
  ::testing::Test::RecordProperty("max_rel_H", std::to_string(c.h));
  ::testing::Test::RecordProperty("max_rel_g", std::to_string(c.g));
  ::testing::Test::RecordProperty("max_rel_label_cost", std::to_string(c.label_cost));
  ::testing::Test::RecordProperty("max_rel_label_pixels", std::to_string(c.label_pixels));
  ::testing::Test::RecordProperty("max_rel_cost", std::to_string(c.cost));
  std::printf("max relative differences: H %.3g g %.3g label_cost %.3g label_pixels %.3g cost %.3g\n", c.h, c.g,
              c.label_cost, c.label_pixels, c.cost);
}

Comparison worstOf(const Comparison& a, const Comparison& b) {
  return {std::max(a.h, b.h), std::max(a.g, b.g), std::max(a.label_cost, b.label_cost),
          std::max(a.label_pixels, b.label_pixels), std::max(a.cost, b.cost)};
}

TEST(CudaMotionAccumulator, MatchesCpuOnSmallLevel) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(61, 45, 1);
  Comparison worst = compareOnScene(s, 0, 4, LabelKind::Blended, true);
  worst = worstOf(worst, compareOnScene(s, 0, 1, LabelKind::OneHot, false));
  record(worst);
}

TEST(CudaMotionAccumulator, MatchesCpuOnAwkwardSizeWithManyLabelCounts) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(131, 97, 1);
  Comparison worst;
  for (int labels : {1, 4, 21})
    for (LabelKind kind : {LabelKind::OneHot, LabelKind::Blended})
      for (bool occlusion : {false, true}) worst = worstOf(worst, compareOnScene(s, 0, labels, kind, occlusion));
  record(worst);
}

TEST(CudaMotionAccumulator, MatchesCpuOnPyramidLevelsAt320x240) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(320, 240, 3, 1);
  Comparison worst;
  for (int level = 0; level < 3; ++level)
    for (LabelKind kind : {LabelKind::OneHot, LabelKind::Blended})
      worst = worstOf(worst, compareOnScene(s, level, level == 0 ? 21 : 4, kind, level != 1));
  record(worst);
}

TEST(CudaMotionAccumulator, ReusesBuffersAcrossLevelsOfDifferentSize) {
  SKIP_WITHOUT_GPU();
  // Large level first, then a smaller one, then a larger one with more labels: stale data must not leak.
  const Scene big = makeScene(160, 120, 1);
  const Scene small = makeScene(33, 17, 1);
  Config config;
  auto cpu = makeCpuMotionAccumulator();
  auto gpu = makeCudaMotionAccumulator();
  for (const Scene* s : {&big, &small, &big}) {
    for (int labels : {3, 9}) {
      const SoftLabels u = makeLabels(s->pair, labels, LabelKind::Blended, 5u);
      cpu->setLevel(s->p1[0], s->p2[0], u, nullptr, config);
      gpu->setLevel(s->p1[0], s->p2[0], u, nullptr, config);
      const std::vector<Vector6d> twists = makeTwists(s->pair, labels, TwistKind::Truth, 1u);
      MotionNormalEquations a, b;
      cpu->accumulate(twists, a);
      gpu->accumulate(twists, b);
      compareSums(b, a, std::to_string(s->p1[0].points.width) + " px wide, " + std::to_string(labels) + " labels");
    }
  }
}

TEST(CudaMotionAccumulator, RepeatedRunsAreBitIdentical) {
  SKIP_WITHOUT_GPU();
  // The Solver promises the same result for the same input (test_core Solver.DeterministicForAGivenSeed):
  // the GPU sums must not depend on scheduling.
  const Scene s = makeScene(160, 120, 1);
  Config config;
  const SoftLabels u = makeLabels(s.pair, 5, LabelKind::Blended, 9u);
  const std::vector<Vector6d> twists = makeTwists(s.pair, 5, TwistKind::Truth, 1u);
  MotionNormalEquations first;
  for (int run = 0; run < 4; ++run) {
    auto gpu = makeCudaMotionAccumulator();
    gpu->setLevel(s.p1[0], s.p2[0], u, nullptr, config);
    MotionNormalEquations out;
    gpu->accumulate(twists, out);
    if (run == 0) {
      first = out;
      continue;
    }
    EXPECT_TRUE(out.H == first.H) << "run " << run << ": max difference " << maxAbs(out.H - first.H);
    EXPECT_TRUE(out.g == first.g) << "run " << run;
    EXPECT_TRUE(out.label_cost == first.label_cost) << "run " << run;
    EXPECT_EQ(out.cost, first.cost) << "run " << run;
    EXPECT_EQ(out.pixels, first.pixels) << "run " << run;
  }
}

TEST(CudaMotionAccumulator, LabelBlocksAreTheFullPassBitForBit) {
  SKIP_WITHOUT_GPU();
  // A cost model's pass skips the label pairs' sums: every value it keeps must be the full pass's, bit for bit
  // (the solver's merge tests read them), and the blocks between labels stay zero. Blended labels, an occlusion mask
  // and a pass after a full one (the blended-pixel buffers then hold the full pass's values).
  const Scene s = makeScene(160, 120, 1);
  Config config;
  const SoftLabels u = makeLabels(s.pair, 6, LabelKind::Blended, 5u);
  const ImageU8 occluded = makeOcclusion(s.pair, 3u);
  const std::vector<Vector6d> twists = makeTwists(s.pair, 6, TwistKind::Truth, 2u);
  auto gpu = makeCudaMotionAccumulator();
  gpu->setLevel(s.p1[0], s.p2[0], u, &occluded, config);
  MotionNormalEquations full, blocks, blocks_first;
  gpu->accumulateLabelBlocks(twists, blocks_first);
  gpu->accumulate(twists, full);
  gpu->accumulateLabelBlocks(twists, blocks);
  double off_diagonal = 0;
  for (int a = 0; a < 6; ++a)
    for (int b = 0; b < 6; ++b) {
      if (a == b) {
        EXPECT_TRUE((blocks.H.block<6, 6>(6 * a, 6 * a) == full.H.block<6, 6>(6 * a, 6 * a))) << "label " << a;
      } else {
        EXPECT_TRUE((blocks.H.block<6, 6>(6 * a, 6 * b).isZero(0.0))) << "labels " << a << ", " << b;
        off_diagonal += (full.H.block<6, 6>(6 * a, 6 * b).cwiseAbs().sum());
      }
    }
  EXPECT_GT(off_diagonal, 0.0) << "the scene must have blended pixels, or the test shows nothing";
  EXPECT_TRUE(blocks.g == full.g);
  EXPECT_TRUE(blocks.label_cost == full.label_cost);
  EXPECT_TRUE(blocks.label_pixels == full.label_pixels);
  EXPECT_EQ(blocks.cost, full.cost);
  EXPECT_EQ(blocks.pixels, full.pixels);
  EXPECT_TRUE(blocks_first.H == blocks.H && blocks_first.g == blocks.g && blocks_first.cost == blocks.cost);
}

TEST(CudaMotionAccumulator, RejectsMismatchedInputs) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(40, 30, 1);
  Config config;
  auto gpu = makeCudaMotionAccumulator();
  MotionNormalEquations out;
  EXPECT_THROW(gpu->accumulate({Vector6d::Zero()}, out), InputError);  // before setLevel
  const SoftLabels u = makeLabels(s.pair, 3, LabelKind::OneHot, 1u);
  gpu->setLevel(s.p1[0], s.p2[0], u, nullptr, config);
  EXPECT_THROW(gpu->accumulate({Vector6d::Zero()}, out), InputError);  // 1 twist for 3 labels
  const SoftLabels wrong(20, 30, 4, 0.25f);
  EXPECT_THROW(gpu->setLevel(s.p1[0], s.p2[0], wrong, nullptr, config), InputError);
  const ImageU8 wrong_mask(40, 29, 1, 0);
  EXPECT_THROW(gpu->setLevel(s.p1[0], s.p2[0], u, &wrong_mask, config), InputError);
}

TEST(CudaMotionAccumulator, CoarseToFineTwistsMatchCpu) {
  SKIP_WITHOUT_GPU();
  const int levels = 3, motion_labels = 4;
  const Scene s = makeScene(320, 240, levels, 0);
  Config config;
  const SoftLabels full = makeLabels(s.pair, motion_labels, LabelKind::Blended, 2u);
  std::vector<Vector6d> twists_cpu(std::size_t(motion_labels), Vector6d::Zero()), twists_gpu = twists_cpu;
  auto cpu = makeCpuMotionAccumulator();
  auto gpu = makeCudaMotionAccumulator();
  ASSERT_EQ(gpu->name(), "cuda");
  double largest_difference = 0, largest_motion = 0;
  for (int level = levels - 1; level >= 0; --level) {
    SoftLabels u = full;
    for (int l = 1; l <= level; ++l) u = downsampleLabels(u, s.p1[l].points.width, s.p1[l].points.height);
    const MotionLevelStats a =
        estimateMotionsAtLevel(s.p1[level], s.p2[level], u, nullptr, twists_cpu, config, cpu.get());
    const MotionLevelStats b =
        estimateMotionsAtLevel(s.p1[level], s.p2[level], u, nullptr, twists_gpu, config, gpu.get());
    EXPECT_EQ(a.iterations, b.iterations) << "level " << level;
    EXPECT_EQ(a.pixels_used, b.pixels_used) << "level " << level;
    for (int i = 0; i < motion_labels; ++i) {
      largest_difference =
          std::max(largest_difference, (twists_cpu[std::size_t(i)] - twists_gpu[std::size_t(i)]).cwiseAbs().maxCoeff());
      largest_motion = std::max(largest_motion, twists_cpu[std::size_t(i)].cwiseAbs().maxCoeff());
    }
  }
  RecordProperty("max_twist_difference", std::to_string(largest_difference));
  std::printf("largest twist difference %.3g (largest twist entry %.3g)\n", largest_difference, largest_motion);
  EXPECT_GT(largest_motion, 1e-3);  // the labels did move
  EXPECT_LE(largest_difference, kTwistTolerance);
}

// The IRLS loop runs on the device (iterateLevel): the same step control and stops as the host loop, with a
// Cholesky of each group of coupled labels instead of the host's LDLT. Blended labels couple every label with
// others: 8 and 10 labels put the group's matrix in shared memory, 30 labels (181x181, 262 KB) in global memory.
TEST(CudaMotionAccumulator, DeviceLoopMatchesTheHostLoopForCoupledLabels) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(320, 240, 1, 1);
  Config config;
  // Every coupling kept (motion_min_coupling 0: the whole groups' factorization), the default (weak ones dropped)
  // and a threshold that keeps only the strongest couplings.
  for (const double min_coupling : {0.0, Config().motion_min_coupling, 0.6})
    for (const int motion_labels : {10, 8, 30}) {  // 10 first: 33 KB of matrix beside 27 KB of static shared memory
      config.motion_min_coupling = min_coupling;
      const SoftLabels u = makeLabels(s.pair, motion_labels, LabelKind::Blended, 5u);
      std::vector<Vector6d> twists_cpu = makeTwists(s.pair, motion_labels, TwistKind::Truth, 3u);
      for (Vector6d& xi : twists_cpu) xi(0) += 0.01;  // 1 cm off: something to estimate
      std::vector<Vector6d> twists_gpu = twists_cpu;
      auto cpu = makeCpuMotionAccumulator();
      auto gpu = makeCudaMotionAccumulator();
      const MotionLevelStats a = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_cpu, config, cpu.get());
      const MotionLevelStats b = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_gpu, config, gpu.get());
      EXPECT_EQ(a.iterations, b.iterations) << motion_labels << " labels";
      EXPECT_EQ(a.stop, b.stop) << motion_labels << " labels: " << toString(a.stop) << " / " << toString(b.stop);
      EXPECT_EQ(a.pixels_used, b.pixels_used) << motion_labels << " labels";
      EXPECT_EQ(a.largest_block, b.largest_block) << motion_labels << " labels, min_coupling " << min_coupling;
      if (min_coupling == 0.0) EXPECT_GE(b.largest_block, motion_labels / 2) << "the labels should be coupled";
      EXPECT_NEAR(a.cost_after, b.cost_after, 1e-6 * a.cost_after);
      double largest_difference = 0, largest_step = 0;
      for (int i = 0; i < motion_labels; ++i) {
        largest_difference = std::max(largest_difference,
                                      (twists_cpu[std::size_t(i)] - twists_gpu[std::size_t(i)]).cwiseAbs().maxCoeff());
        largest_step = std::max(
            largest_step, std::abs(twists_cpu[std::size_t(i)](0) -
                                   makeTwists(s.pair, motion_labels, TwistKind::Truth, 3u)[std::size_t(i)](0) - 0.01));
      }
      std::printf(
          "%d labels, min_coupling %.2f: largest twist difference %.3g, largest x step %.3g, largest group %d\n",
          motion_labels, min_coupling, largest_difference, largest_step, b.largest_block);
      EXPECT_GT(largest_step, 1e-4) << "the labels did move";
      EXPECT_LE(largest_difference, kTwistTolerance) << motion_labels << " labels";
    }
}

// One level's IRLS loop on the host and on the device from the same labels and twists: the same largest group
// (`largest_block`), iterations and stop, and twists within kTwistTolerance. Returns the device's twists.
std::vector<Vector6d> expectDeviceLoopMatchesHost(const Scene& s, const SoftLabels& u,
                                                  const std::vector<Vector6d>& start, const Config& config,
                                                  int largest_block) {
  std::vector<Vector6d> twists_cpu = start, twists_gpu = start;
  auto cpu = makeCpuMotionAccumulator();
  auto gpu = makeCudaMotionAccumulator();
  const MotionLevelStats a = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_cpu, config, cpu.get());
  const MotionLevelStats b = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_gpu, config, gpu.get());
  EXPECT_EQ(a.largest_block, largest_block);
  EXPECT_EQ(b.largest_block, largest_block);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.stop, b.stop) << toString(a.stop) << " / " << toString(b.stop);
  double largest_difference = 0;
  for (std::size_t i = 0; i < start.size(); ++i)
    largest_difference = std::max(largest_difference, (twists_cpu[i] - twists_gpu[i]).cwiseAbs().maxCoeff());
  EXPECT_LE(largest_difference, kTwistTolerance);
  return twists_gpu;
}

// A star of couplings (label 0 blends with every other label, the others only with label 0): one group of six whose
// off-diagonal blocks are mostly zero before the factorization (eliminating the hub first fills them in); the device's
// block Cholesky gives the same solution as the host's LDLT of the whole group.
TEST(CudaMotionAccumulator, DeviceLoopMatchesTheHostLoopForAStarOfCoupledLabels) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(320, 240, 1, 0);
  Config config;
  config.motion_min_coupling = 0.0;  // these couplings are weak (a quarter of the pixels at 0.3): keep them all
  const int motion_labels = 6, W = s.pair.frame1.width(), H = s.pair.frame1.height();
  SoftLabels u(W, H, motion_labels + 1, 0.f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const int own = std::min(motion_labels - 1, x * motion_labels / W);  // vertical bands
      if (own > 0 && (x + y) % 4 == 0) {
        u.at(own, x, y) = 0.7f;
        u.at(0, x, y) = 0.3f;
      } else {
        u.at(own, x, y) = 1.f;
      }
    }
  std::vector<Vector6d> twists(std::size_t(motion_labels), Vector6d::Zero());
  for (int i = 0; i < motion_labels; ++i) twists[std::size_t(i)] << 0.005 * i, -0.004, 0.01, 0.002, -0.003 * i, 0.001;
  expectDeviceLoopMatchesHost(s, u, twists, config, motion_labels);
}

// Groups split at weak couplings, on the device as on the host (test::labelsWithWeakAndStrongCouplings: labels 0-1
// and 1-2 strongly coupled, 0-2 weakly inside the group {0, 1, 2}, so kept in its matrix, 2-3 weakly only: label 3 is
// solved apart). With every coupling kept all four form one group; with the default
// the largest group has three labels and the dropped 2-3 coupling changes the step. Had the device zeroed the weak
// 0-2 block inside the group, its step would differ from the host's by about 5e-4 (measured when it did).
TEST(CudaMotionAccumulator, DeviceLoopSplitsGroupsAtWeakCouplingsAsTheHostLoopDoes) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(320, 240, 1, 0);
  const int motion_labels = 4;
  const SoftLabels u = test::labelsWithWeakAndStrongCouplings(s.pair.frame1.width(), s.pair.frame1.height());
  std::vector<Vector6d> start(std::size_t(motion_labels), Vector6d::Zero());
  for (int i = 0; i < motion_labels; ++i) start[std::size_t(i)] << 0.004 * i, -0.006, 0.01, 0.002, -0.002 * i, 0.001;
  Config config;
  config.motion_iterations_per_level = 2;  // one step, then its check: the steps themselves are compared
  std::vector<Vector6d> kept_all;
  for (const double min_coupling : {0.0, Config().motion_min_coupling}) {
    config.motion_min_coupling = min_coupling;
    std::vector<Vector6d> twists_cpu = start, twists_gpu = start;
    auto cpu = makeCpuMotionAccumulator();
    auto gpu = makeCudaMotionAccumulator();
    const MotionLevelStats a = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_cpu, config, cpu.get());
    const MotionLevelStats b = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_gpu, config, gpu.get());
    const int expected_group = min_coupling == 0.0 ? 4 : 3;
    EXPECT_EQ(a.largest_block, expected_group) << "min_coupling " << min_coupling;
    EXPECT_EQ(b.largest_block, expected_group) << "min_coupling " << min_coupling;
    EXPECT_EQ(a.iterations, b.iterations);
    double largest_difference = 0;
    for (int i = 0; i < motion_labels; ++i)
      largest_difference =
          std::max(largest_difference, (twists_cpu[std::size_t(i)] - twists_gpu[std::size_t(i)]).cwiseAbs().maxCoeff());
    EXPECT_LE(largest_difference, kTwistTolerance) << "min_coupling " << min_coupling;
    if (min_coupling == 0.0) {
      kept_all = twists_gpu;
      continue;
    }
    double dropped_effect = 0;
    for (int i = 0; i < motion_labels; ++i)
      dropped_effect =
          std::max(dropped_effect, (kept_all[std::size_t(i)] - twists_gpu[std::size_t(i)]).cwiseAbs().maxCoeff());
    std::printf("weak coupling dropped: host/device difference %.3g, change of the step %.3g\n", largest_difference,
                dropped_effect);
    EXPECT_GT(dropped_effect, 10 * kTwistTolerance) << "dropping the weak 2-3 coupling should change the step";
  }
}

// Without damping (motion_damping 0, which Config allows) only a 1e-9 ridge keeps a group's matrix definite; the
// device's unpivoted Cholesky must still give a step (a pivot floor), as the host's pivoted LDLT does: the same stop
// and iterations, finite twists and the same cost.
TEST(CudaMotionAccumulator, DeviceLoopWithoutDampingStillSteps) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(320, 240, 1, 1);
  Config config;
  config.motion_damping = 0.0;
  config.motion_min_coupling = 0.0;  // groups of coupled labels, factored by the whole block
  const int motion_labels = 8;
  const SoftLabels u = makeLabels(s.pair, motion_labels, LabelKind::Blended, 9u);
  std::vector<Vector6d> twists_cpu = makeTwists(s.pair, motion_labels, TwistKind::Truth, 3u);
  for (Vector6d& xi : twists_cpu) xi(1) -= 0.01;
  std::vector<Vector6d> twists_gpu = twists_cpu;
  auto cpu = makeCpuMotionAccumulator();
  auto gpu = makeCudaMotionAccumulator();
  const MotionLevelStats a = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_cpu, config, cpu.get());
  const MotionLevelStats b = estimateMotionsAtLevel(s.p1[0], s.p2[0], u, nullptr, twists_gpu, config, gpu.get());
  EXPECT_NE(b.stop, MotionStop::SolveFailed);
  EXPECT_EQ(a.stop, b.stop) << toString(a.stop) << " / " << toString(b.stop);
  EXPECT_EQ(a.iterations, b.iterations);
  for (const Vector6d& xi : twists_gpu) EXPECT_TRUE(xi.allFinite());
  EXPECT_NEAR(a.cost_after, b.cost_after, 1e-6 * a.cost_after);
}

// Two interleaved chains of coupled labels (vertical bands; even labels on the left half, odd ones on the right, each
// band blending with the next band of its half): two groups whose members are not contiguous label numbers, found by
// the device's label propagation in as many rounds as a chain has links, in the host's order (roots ascending,
// members ascending): the same groups, steps and stops as the host loop.
TEST(CudaMotionAccumulator, DeviceLoopGroupsTwoInterleavedChainsAsTheHostLoopDoes) {
  SKIP_WITHOUT_GPU();
  const Scene s = makeScene(320, 240, 1, 0);
  Config config;
  config.motion_min_coupling = 0.0;  // every coupling joins groups
  const int chain = 8, motion_labels = 2 * chain, W = s.pair.frame1.width(), H = s.pair.frame1.height();
  SoftLabels u(W, H, motion_labels + 1, 0.f);
  const int half = W / 2, band = half / chain;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const int side = x < half ? 0 : 1;
      const int k = std::min(chain - 1, (x - side * half) / band);
      const int own = 2 * k + side, next = 2 * (k + 1) + side;
      const bool blend = k + 1 < chain && (x - side * half) % band >= band - 4;  // the band's last 4 columns
      if (blend) {
        u.at(own, x, y) = 0.6f;
        u.at(next, x, y) = 0.4f;
      } else {
        u.at(own, x, y) = 1.f;
      }
    }
  std::vector<Vector6d> twists(std::size_t(motion_labels), Vector6d::Zero());
  for (int i = 0; i < motion_labels; ++i) twists[std::size_t(i)] << 0.003 * i, -0.004, 0.01, 0.002, -0.001 * i, 0.001;
  const std::vector<Vector6d> moved = expectDeviceLoopMatchesHost(s, u, twists, config, chain);
  double largest_step = 0;
  for (const Vector6d& xi : moved) largest_step = std::max(largest_step, std::abs(xi(1) + 0.004));
  EXPECT_GT(largest_step, 1e-4) << "the labels did move";
}

// The whole solver on both backends: test_solve_backend_cuda.cpp, SolverMatchesCpuOnSyntheticScenes.

}  // namespace
}  // namespace mc_flow
