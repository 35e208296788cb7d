// Tests of the synthetic RGB-D scene generator: its ground truth is what every end-to-end test trusts,
// so it is checked here against the rendered images themselves (warping frame 2 with the ground truth
// must reproduce frame 1) and against the published twists.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <set>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace mc_flow {
namespace {

SyntheticSceneOptions optionsFor(int variant, int width = 320, int height = 240) {
  SyntheticSceneOptions o;
  o.variant = variant;
  o.width = width;
  o.height = height;
  return o;
}

/// Bilinear sample of channel 0; NaN outside [0, W-1] x [0, H-1].
double bilinear(const ImageF& img, double x, double y) {
  if (!(x >= 0.0 && y >= 0.0 && x <= img.width - 1 && y <= img.height - 1)) return NAN;
  const int x0 = std::min(int(x), img.width - 2), y0 = std::min(int(y), img.height - 2);
  const double a = x - x0, b = y - y0;
  return (1 - b) * ((1 - a) * img(x0, y0) + a * img(x0 + 1, y0)) +
         b * ((1 - a) * img(x0, y0 + 1) + a * img(x0 + 1, y0 + 1));
}

/// True when the four frame-2 depths around (x, y) are valid and within `tolerance` of z (one surface).
bool neighboursOnSurface(const ImageF& depth, double x, double y, double z, double tolerance) {
  const int x0 = std::min(int(x), depth.width - 2), y0 = std::min(int(y), depth.height - 2);
  for (int dy = 0; dy < 2; ++dy)
    for (int dx = 0; dx < 2; ++dx) {
      const float d = depth(x0 + dx, y0 + dy);
      if (!isValidDepth(d) || std::abs(d - z) > tolerance) return false;
    }
  return true;
}

Eigen::Vector3d backProject(const Intrinsics& K, int x, int y, double z) {
  return {(x - K.cx) / K.fx * z, (y - K.cy) / K.fy * z, z};
}

Eigen::Vector2d project(const Intrinsics& K, const Eigen::Vector3d& P) {
  return {K.fx * P.x() / P.z() + K.cx, K.fy * P.y() / P.z() + K.cy};
}

Eigen::Vector3d transform(const Eigen::Matrix4d& T, const Eigen::Vector3d& P) {
  return T.topLeftCorner<3, 3>() * P + T.topRightCorner<3, 1>();
}

const SyntheticPart& partById(const SyntheticPair& pair, int id) {
  for (const SyntheticPart& p : pair.parts)
    if (p.id == id) return p;
  throw std::runtime_error("no part " + std::to_string(id));
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  const std::size_t k = std::min(v.size() - 1, std::size_t(q * (v.size() - 1)));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

double rotationAngle(const Eigen::Matrix4d& T) {
  return Eigen::AngleAxisd(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).angle();
}

class SyntheticVariants : public ::testing::TestWithParam<int> {};

TEST(SyntheticScene, RenderingIsDeterministic) {
  SyntheticSceneOptions o = optionsFor(1);
  o.intensity_noise = 0.01;
  o.depth_noise = 0.002;
  const SyntheticPair a = renderSyntheticPair(o), b = renderSyntheticPair(o);
  EXPECT_EQ(a.color1.data, b.color1.data);
  EXPECT_EQ(a.color2.data, b.color2.data);
  EXPECT_EQ(a.frame1.intensity.data, b.frame1.intensity.data);
  EXPECT_EQ(a.frame2.depth.data, b.frame2.depth.data);
  EXPECT_EQ(a.gt_parts.data, b.gt_parts.data);
  EXPECT_EQ(a.gt_occlusion.data, b.gt_occlusion.data);
  ASSERT_EQ(a.gt_optical_flow.data.size(), b.gt_optical_flow.data.size());
  for (std::size_t i = 0; i < a.gt_optical_flow.data.size(); ++i) {
    const float p = a.gt_optical_flow.data[i], q = b.gt_optical_flow.data[i];
    ASSERT_TRUE((std::isnan(p) && std::isnan(q)) || p == q) << "index " << i;
  }
}

TEST(SyntheticScene, SizesAndIntrinsics) {
  const SyntheticPair ref = renderSyntheticPair(optionsFor(0));
  EXPECT_DOUBLE_EQ(ref.intrinsics.fx, 263.7);
  EXPECT_DOUBLE_EQ(ref.intrinsics.fy, 263.7);
  EXPECT_DOUBLE_EQ(ref.intrinsics.cx, 159.5);
  EXPECT_DOUBLE_EQ(ref.intrinsics.cy, 119.5);
  std::map<int, double> ref_fraction;
  for (int id : ref.gt_parts.data) ref_fraction[id] += 1.0 / ref.gt_parts.pixelCount();

  const int sizes[][2] = {{160, 120}, {640, 480}, {631, 479}};
  for (const auto& s : sizes) {
    const int W = s[0], H = s[1];
    const SyntheticPair p = renderSyntheticPair(optionsFor(0, W, H));
    SCOPED_TRACE(std::to_string(W) + "x" + std::to_string(H));
    EXPECT_NEAR(p.intrinsics.fx, 263.7 * W / 320.0, 1e-9);
    EXPECT_NEAR(p.intrinsics.fy, 263.7 * H / 240.0, 1e-9);
    EXPECT_NEAR(p.intrinsics.cx, 160.0 * W / 320.0 - 0.5, 1e-9);
    EXPECT_NEAR(p.intrinsics.cy, 120.0 * H / 240.0 - 0.5, 1e-9);
    EXPECT_TRUE(p.frame1.intensity.sameSize(W, H) && p.frame1.depth.sameSize(W, H));
    EXPECT_TRUE(p.frame2.intensity.sameSize(W, H) && p.frame2.depth.sameSize(W, H));
    EXPECT_TRUE(p.color1.sameSize(W, H) && p.color2.sameSize(W, H));
    EXPECT_EQ(p.color1.channels, 3);
    EXPECT_EQ(p.gt_scene_flow.channels, 3);
    EXPECT_EQ(p.gt_optical_flow.channels, 2);
    EXPECT_TRUE(p.gt_scene_flow.sameSize(W, H) && p.gt_optical_flow.sameSize(W, H));
    EXPECT_TRUE(p.gt_occlusion.sameSize(W, H) && p.gt_parts.sameSize(W, H));
    // The same scene seen at another resolution: each part covers about the same image fraction.
    std::map<int, double> fraction;
    for (int id : p.gt_parts.data) fraction[id] += 1.0 / p.gt_parts.pixelCount();
    for (const auto& [id, f] : ref_fraction) EXPECT_NEAR(fraction[id], f, 0.1 * f + 0.002) << "part " << id;
  }
}

TEST(SyntheticScene, IntensityIsGreyOfColourAndInRange) {
  const SyntheticPair p = renderSyntheticPair(optionsFor(0));
  for (int i = 0; i < 2; ++i) {
    const ImageU8& c = i == 0 ? p.color1 : p.color2;
    const ImageF& g = i == 0 ? p.frame1.intensity : p.frame2.intensity;
    for (std::size_t k = 0; k < g.pixelCount(); ++k) {
      const double grey = (0.299 * c.data[3 * k] + 0.587 * c.data[3 * k + 1] + 0.114 * c.data[3 * k + 2]) / 255.0;
      ASSERT_NEAR(g.data[k], grey, 1e-6) << "pixel " << k;
      ASSERT_GE(g.data[k], 0.1f);
      ASSERT_LE(g.data[k], 0.9f);
    }
  }
}

TEST(SyntheticScene, InvalidOptionsThrow) {
  SyntheticSceneOptions o;
  o.width = 0;
  EXPECT_THROW(renderSyntheticPair(o), InputError);
  o = SyntheticSceneOptions();
  o.variant = syntheticVariantCount();
  EXPECT_THROW(renderSyntheticPair(o), InputError);
  o = SyntheticSceneOptions();
  o.depth_noise = -1.0;
  EXPECT_THROW(renderSyntheticPair(o), InputError);
  o = SyntheticSceneOptions();
  RgbdFrame f;
  ImageU8 c;
  Intrinsics K;
  EXPECT_THROW(renderSyntheticFrame(o, -1, f, c, K), InputError);
}

TEST(SyntheticScene, BackgroundTwist) {
  EXPECT_TRUE(partById(renderSyntheticPair(optionsFor(0)), 0).twist.isZero(0.0));
  EXPECT_TRUE(partById(renderSyntheticPair(optionsFor(1)), 0).twist.isZero(0.0));
  const SyntheticPair moving = renderSyntheticPair(optionsFor(2));
  EXPECT_GT(partById(moving, 0).twist.norm(), 0.01);
}

// Camera-only scenes: every part, the arm's links included, moves with the static scene's one apparent motion,
// and the ground-truth scene flow of every point is that motion (up to the renderer's float rounding).
TEST(SyntheticScene, CameraOnlyScenesMoveAsOneRigidBody) {
  for (int variant = 0; variant < syntheticVariantCount(); ++variant) {
    SyntheticSceneOptions o = optionsFor(variant, 160, 120);
    o.camera_only = true;
    o.camera_only_translation_m = Eigen::Vector3d(0.05, -0.02, 0.04);
    o.camera_only_rotation_deg = Eigen::Vector3d(2.0, -3.0, 1.0);
    const SyntheticPair pair = renderSyntheticPair(o);
    const Vector6d background = partById(pair, 0).twist;
    EXPECT_GT(background.norm(), 0.05);
    for (const SyntheticPart& part : pair.parts)
      EXPECT_TRUE(part.twist.isApprox(background, 1e-9)) << "variant " << variant << " part " << part.name;
    const Eigen::Matrix4d T = se3Exp(background);
    int checked = 0;
    for (int y = 0; y < pair.frame1.depth.height; ++y)
      for (int x = 0; x < pair.frame1.depth.width; ++x) {
        const float z = pair.frame1.depth(x, y);
        if (!(z > 0.f) || std::isnan(pair.gt_scene_flow(x, y, 0))) continue;
        const Eigen::Vector3d P((x - pair.intrinsics.cx) / pair.intrinsics.fx * z,
                                (y - pair.intrinsics.cy) / pair.intrinsics.fy * z, z);
        const Eigen::Vector3d flow = T.topLeftCorner<3, 3>() * P + T.topRightCorner<3, 1>() - P;
        for (int c = 0; c < 3; ++c) ASSERT_NEAR(pair.gt_scene_flow(x, y, c), flow(c), 1e-4) << x << "," << y;
        ++checked;
      }
    EXPECT_GT(checked, 10000) << "variant " << variant;
  }
  SyntheticSceneOptions bad = optionsFor(0);
  bad.camera_only = true;
  bad.camera_only_rotation_deg = Eigen::Vector3d(90.0, 0.0, 0.0);
  EXPECT_THROW(renderSyntheticPair(bad), InputError);
}

TEST(SyntheticScene, PartsFollowingTheRoomMoveWithItOverTheSequence) {
  // Variant 2 with its stream events: the camera moves (the room has a twist of its own); with parts_follow_room every
  // part takes the room's twist in every pair, and the room's twist is the one of the scene with moving parts.
  SyntheticSceneOptions moving = optionsFor(2, 160, 120);
  moving.stream_events = true;
  SyntheticSceneOptions following = moving;
  following.parts_follow_room = true;
  for (const int t : {0, 5, 12}) {
    const std::vector<SyntheticPart> parts = syntheticSequenceMotions(following, t);
    const std::vector<SyntheticPart> reference = syntheticSequenceMotions(moving, t);
    ASSERT_FALSE(parts.empty());
    Vector6d room = Vector6d::Zero(), reference_room = Vector6d::Zero();
    for (const SyntheticPart& p : parts)
      if (p.id == 0) room = p.twist;
    for (const SyntheticPart& p : reference)
      if (p.id == 0) reference_room = p.twist;
    EXPECT_GT(room.norm(), 1e-4) << "frame " << t;
    EXPECT_TRUE(room.isApprox(reference_room, 1e-12)) << "frame " << t;
    int differs = 0;
    for (std::size_t k = 0; k < parts.size(); ++k) {
      EXPECT_TRUE(parts[k].twist.isApprox(room, 1e-9)) << "frame " << t << " part " << parts[k].name;
      differs += reference[k].twist.isApprox(room, 1e-6) ? 0 : 1;
    }
    EXPECT_GT(differs, 0) << "frame " << t << ": the reference scene's parts move on their own";
  }
}

TEST(SyntheticScene, MotionScaleScalesTwistsAndZeroFreezesTheScene) {
  SyntheticSceneOptions o = optionsFor(2);
  const SyntheticPair one = renderSyntheticPair(o);
  o.motion_scale = 2.0;
  const std::vector<SyntheticPart> two = syntheticSequenceMotions(o, 0);
  ASSERT_EQ(two.size(), one.parts.size());
  for (std::size_t k = 0; k < two.size(); ++k) EXPECT_TRUE(two[k].twist.isApprox(2.0 * one.parts[k].twist, 1e-12));

  o.motion_scale = 0.0;
  const SyntheticPair still = renderSyntheticPair(o);
  EXPECT_EQ(still.frame1.depth.data, still.frame2.depth.data);
  EXPECT_EQ(still.color1.data, still.color2.data);
  for (std::size_t i = 0; i < still.gt_optical_flow.data.size(); ++i) {
    const float f = still.gt_optical_flow.data[i];
    ASSERT_TRUE(std::isnan(f) || std::abs(f) < 1e-4f) << f;
  }
  for (std::uint8_t occ : still.gt_occlusion.data) ASSERT_EQ(occ, 0);
}

TEST(SyntheticScene, PairIsFramesZeroAndOneOfTheSequence) {
  SyntheticSceneOptions o = optionsFor(2, 160, 120);
  o.intensity_noise = 0.02;
  o.depth_noise = 0.001;
  const SyntheticPair pair = renderSyntheticPair(o);
  RgbdFrame f0, f1;
  ImageU8 c0, c1;
  Intrinsics K;
  renderSyntheticFrame(o, 0, f0, c0, K);
  renderSyntheticFrame(o, 1, f1, c1, K);
  EXPECT_EQ(K.fx, pair.intrinsics.fx);
  EXPECT_EQ(f0.intensity.data, pair.frame1.intensity.data);
  EXPECT_EQ(f0.depth.data, pair.frame1.depth.data);
  EXPECT_EQ(f1.intensity.data, pair.frame2.intensity.data);
  EXPECT_EQ(f1.depth.data, pair.frame2.depth.data);
  EXPECT_EQ(c0.data, pair.color1.data);
  EXPECT_EQ(c1.data, pair.color2.data);
  const std::vector<SyntheticPart> m0 = syntheticSequenceMotions(o, 0);
  ASSERT_EQ(m0.size(), pair.parts.size());
  for (std::size_t k = 0; k < m0.size(); ++k) {
    EXPECT_EQ(m0[k].id, pair.parts[k].id);
    EXPECT_TRUE(m0[k].twist == pair.parts[k].twist) << m0[k].name;
  }
}

TEST(SyntheticScene, NoiseHasTheRequestedStatistics) {
  SyntheticSceneOptions o = optionsFor(0);
  const SyntheticPair clean = renderSyntheticPair(o);
  o.intensity_noise = 0.02;
  o.depth_noise = 0.003;
  const SyntheticPair noisy = renderSyntheticPair(o);
  double si = 0, sii = 0, sd = 0, sdd = 0;
  int ni = 0, nd = 0;
  for (std::size_t i = 0; i < clean.frame1.intensity.pixelCount(); ++i) {
    const double ci = clean.frame1.intensity.data[i];
    if (ci > 0.2 && ci < 0.8) {  // away from the clamp
      const double e = noisy.frame1.intensity.data[i] - ci;
      si += e;
      sii += e * e;
      ++ni;
    }
    const double z = clean.frame1.depth.data[i];
    if (z > 0) {
      ASSERT_GT(noisy.frame1.depth.data[i], 0.f);
      const double e = (noisy.frame1.depth.data[i] - z) / (z * z);
      sd += e;
      sdd += e * e;
      ++nd;
    } else {
      ASSERT_EQ(noisy.frame1.depth.data[i], 0.f);
    }
  }
  ASSERT_GT(ni, 10000);
  EXPECT_NEAR(si / ni, 0.0, 0.001);
  EXPECT_NEAR(std::sqrt(sii / ni), 0.02, 0.002);
  EXPECT_NEAR(sd / nd, 0.0, 0.0002);
  EXPECT_NEAR(std::sqrt(sdd / nd), 0.003, 0.0003);
  // Another seed gives other noise; the two frames of a pair get independent noise.
  o.seed = 2;
  const SyntheticPair other = renderSyntheticPair(o);
  EXPECT_NE(other.frame1.intensity.data, noisy.frame1.intensity.data);
  EXPECT_NE(other.frame1.depth.data, noisy.frame1.depth.data);
  double s12 = 0, s11 = 0, s22 = 0;
  for (std::size_t i = 0; i < clean.frame1.intensity.pixelCount(); ++i) {
    const double n1 = noisy.frame1.intensity.data[i] - clean.frame1.intensity.data[i];
    const double n2 = noisy.frame2.intensity.data[i] - clean.frame2.intensity.data[i];
    s12 += n1 * n2;
    s11 += n1 * n1;
    s22 += n2 * n2;
  }
  EXPECT_LT(std::abs(s12) / std::sqrt(s11 * s22), 0.03);  // 76800 samples: |corr| of independent noise ~ 0.004
}

// The ground truth against the images it describes (every variant).
/// Warps frame 2 onto frame 1 with the ground truth; errors of moving pixels, counts of the others.
struct WarpCheck {
  std::vector<double> intensity_error, depth_error;  ///< moving pixels: |dI|, |dZ| / Z
  int valid = 0, occluded = 0, checked = 0, still = 0;
  double meanIntensityError() const {
    return std::accumulate(intensity_error.begin(), intensity_error.end(), 0.0) /
           std::max<std::size_t>(1, intensity_error.size());
  }
  void print(const std::string& name) const {
    std::printf(
        "%s: %d of %d valid pixels checked, %d static; moving: |dI| mean %.4f p50 %.4f p95 %.4f; "
        "|dZ|/Z p50 %.2e p99 %.2e; occluded %d\n",
        name.c_str(), checked, valid, still, meanIntensityError(), percentile(intensity_error, 0.5),
        percentile(intensity_error, 0.95), percentile(depth_error, 0.5), percentile(depth_error, 0.99), occluded);
  }
};

void checkWarp(const SyntheticPair& p, WarpCheck& out) {
  const int W = p.frame1.width(), H = p.frame1.height();
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float z1 = p.frame1.depth(x, y);
      const float u = p.gt_optical_flow(x, y, 0), v = p.gt_optical_flow(x, y, 1);
      if (!isValidDepth(z1)) {
        ASSERT_TRUE(std::isnan(u) && std::isnan(p.gt_scene_flow(x, y, 2))) << x << "," << y;
        continue;
      }
      ASSERT_TRUE(std::isfinite(u) && std::isfinite(v) && std::isfinite(p.gt_scene_flow(x, y, 0)));
      ++out.valid;
      if (p.gt_occlusion(x, y)) {
        ++out.occluded;
        continue;
      }
      const double x2 = x + u, y2 = y + v, z2 = z1 + p.gt_scene_flow(x, y, 2);
      // Interpolating across a depth edge mixes two surfaces; keep the samples inside one surface.
      if (x2 < 0 || y2 < 0 || x2 > W - 1 || y2 > H - 1 || !neighboursOnSurface(p.frame2.depth, x2, y2, z2, 0.05))
        continue;
      ++out.checked;
      const double di = std::abs(bilinear(p.frame2.intensity, x2, y2) - p.frame1.intensity(x, y));
      const double dz = std::abs(bilinear(p.frame2.depth, x2, y2) - z2) / z2;
      if (std::hypot(u, v) < 1e-6) {
        // A static surface stays on the pixel grid: no interpolation error, only rounding.
        ++out.still;
        ASSERT_LT(di, 1e-6) << x << "," << y;
        ASSERT_LT(dz, 1e-6) << x << "," << y;
        continue;
      }
      out.intensity_error.push_back(di);
      out.depth_error.push_back(dz);
    }
}

TEST_P(SyntheticVariants, GroundTruthWarpsFrame2OntoFrame1) {
  WarpCheck c;
  checkWarp(renderSyntheticPair(optionsFor(GetParam())), c);
  if (HasFatalFailure()) return;
  c.print("variant " + std::to_string(GetParam()));
  EXPECT_GT(c.checked, 0.85 * c.valid);
  EXPECT_GT(c.intensity_error.size(), 5000u);
  // Bilinear interpolation of a texture with ~2-3 px features: errors of a few grey levels on average.
  // Measured at 320x240: mean 0.004-0.009, p50 <= 0.004, p95 <= 0.033 (variant 2, everything moving).
  EXPECT_LT(c.meanIntensityError(), 0.015);
  EXPECT_LT(percentile(c.intensity_error, 0.5), 0.008);
  EXPECT_LT(percentile(c.intensity_error, 0.95), 0.05);
  // Depth of a plane is not bilinear in the pixel grid, but nearly so over one pixel; the tail is box
  // edges, where the surface bends (measured p50 < 1e-6, p99 < 2e-3).
  EXPECT_LT(percentile(c.depth_error, 0.5), 1e-5);
  EXPECT_LT(percentile(c.depth_error, 0.99), 4e-3);
  // Occlusions exist but are a small fraction.
  EXPECT_GT(c.occluded, 0.002 * c.valid);
  EXPECT_LT(c.occluded, 0.1 * c.valid);
}

TEST(SyntheticScene, GroundTruthHoldsAtOtherSizes) {
  // Variant 2 (everything moves). Coarser images sample the same texture more sparsely, so the
  // interpolation error grows as the size shrinks; the depth check stays tight.
  const struct {
    int width, height;
    double max_mean, max_p95;
  } cases[] = {{160, 120, 0.035, 0.13}, {631, 479, 0.01, 0.03}};
  for (const auto& k : cases) {
    WarpCheck c;
    checkWarp(renderSyntheticPair(optionsFor(2, k.width, k.height)), c);
    if (HasFatalFailure()) return;
    c.print(std::to_string(k.width) + "x" + std::to_string(k.height));
    EXPECT_GT(c.checked, 0.8 * c.valid);
    EXPECT_LT(c.meanIntensityError(), k.max_mean);
    EXPECT_LT(percentile(c.intensity_error, 0.95), k.max_p95);
    EXPECT_LT(percentile(c.depth_error, 0.5), 1e-5);
    EXPECT_LT(percentile(c.depth_error, 0.99), 8e-3);
  }
}

TEST_P(SyntheticVariants, OccludedPixelsAreHiddenOrOutOfView) {
  const SyntheticPair p = renderSyntheticPair(optionsFor(GetParam()));
  const int W = p.frame1.width(), H = p.frame1.height();
  int occluded = 0, explained = 0, visible = 0, visible_consistent = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!isValidDepth(p.frame1.depth(x, y))) continue;
      const double x2 = x + p.gt_optical_flow(x, y, 0), y2 = y + p.gt_optical_flow(x, y, 1);
      const double z2 = p.frame1.depth(x, y) + p.gt_scene_flow(x, y, 2);
      const int xi = int(std::lround(x2)), yi = int(std::lround(y2));
      const bool in_view = xi >= 0 && yi >= 0 && xi < W && yi < H;
      const float seen = in_view ? p.frame2.depth(xi, yi) : 0.f;
      if (p.gt_occlusion(x, y)) {
        ++occluded;
        explained += !in_view || (isValidDepth(seen) && seen < z2 - 0.01);
      } else {
        ++visible;
        visible_consistent += in_view && isValidDepth(seen) && std::abs(seen - z2) < 0.05;
      }
    }
  // Nearest-pixel look-ups disagree with the exact visibility test only along silhouettes.
  EXPECT_GT(explained, 0.8 * occluded);
  EXPECT_GT(visible_consistent, 0.98 * visible);
}

TEST_P(SyntheticVariants, RigidPartsMoveExactlyByTheirTwist) {
  const SyntheticPair p = renderSyntheticPair(optionsFor(GetParam()));
  const int W = p.frame1.width(), H = p.frame1.height();
  const int upper_id = p.parts[p.parts.size() - 2].id, fore_id = p.parts.back().id;
  ASSERT_EQ(p.parts[p.parts.size() - 2].name, "upper_arm");
  ASSERT_EQ(p.parts.back().name, "forearm");
  std::map<int, int> count, exact;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float z = p.frame1.depth(x, y);
      if (!isValidDepth(z)) continue;
      const int id = p.gt_parts(x, y);
      const Eigen::Vector3d P = backProject(p.intrinsics, x, y, z);
      const Eigen::Vector3d P2 = transform(se3Exp(partById(p, id).twist), P);
      const Eigen::Vector3d sf(p.gt_scene_flow(x, y, 0), p.gt_scene_flow(x, y, 1), p.gt_scene_flow(x, y, 2));
      const Eigen::Vector2d of(p.gt_optical_flow(x, y, 0), p.gt_optical_flow(x, y, 1));
      // Float depth (relative error 6e-8) and float storage bound the error far below 1 um and 1e-3 px.
      const bool match =
          (sf - (P2 - P)).norm() < 1e-6 && (of - (project(p.intrinsics, P2) - Eigen::Vector2d(x, y))).norm() < 1e-3;
      ++count[id];
      exact[id] += match;
      if (id != upper_id && id != fore_id) ASSERT_TRUE(match) << "part " << id << " at " << x << "," << y;
    }
  for (const SyntheticPart& part : p.parts) {
    EXPECT_GE(count[part.id], 400) << part.name;  // every part is clearly visible
  }
  // Arm links are rigid away from the elbow.
  EXPECT_GT(exact[upper_id], 0.6 * count[upper_id]);
  EXPECT_GT(exact[fore_id], 0.6 * count[fore_id]);
}

TEST_P(SyntheticVariants, ElbowFlowBlendsTheTwoLinks) {
  const SyntheticPair p = renderSyntheticPair(optionsFor(GetParam()));
  const SyntheticPart& upper = p.parts[p.parts.size() - 2];
  const SyntheticPart& fore = p.parts.back();
  const Eigen::Matrix4d Ta = se3Exp(upper.twist), Tb = se3Exp(fore.twist);
  // The links differ by a few degrees.
  const double relative_angle = rotationAngle(Tb * Ta.inverse());
  EXPECT_GT(relative_angle, 2.0 * M_PI / 180);
  EXPECT_LT(relative_angle, 6.0 * M_PI / 180);
  int between = 0, arm = 0, blend_visible = 0;
  std::vector<double> blend_intensity_error, blend_depth_error;
  for (int y = 0; y < p.frame1.height(); ++y)
    for (int x = 0; x < p.frame1.width(); ++x) {
      const int id = p.gt_parts(x, y);
      if (id != upper.id && id != fore.id) continue;
      ++arm;
      const Eigen::Vector3d P = backProject(p.intrinsics, x, y, p.frame1.depth(x, y));
      const Eigen::Vector2d fa = project(p.intrinsics, transform(Ta, P)), fb = project(p.intrinsics, transform(Tb, P));
      const Eigen::Vector2d gt = Eigen::Vector2d(x + p.gt_optical_flow(x, y, 0), y + p.gt_optical_flow(x, y, 1));
      const Eigen::Vector2d d = fb - fa;
      if (d.norm() < 0.3) continue;
      const double alpha = (gt - fa).dot(d) / d.squaredNorm();
      const double off_line = (gt - fa - alpha * d).norm();
      const bool blended = alpha > 0.1 && alpha < 0.9 && off_line < 0.05;
      between += blended;
      const double z2 = P.z() + p.gt_scene_flow(x, y, 2);
      if (blended && !p.gt_occlusion(x, y) && gt.x() >= 0 && gt.y() >= 0 && gt.x() <= p.frame2.width() - 1 &&
          gt.y() <= p.frame2.height() - 1) {
        ++blend_visible;
        // Along the silhouette the interpolation mixes arm and wall: compare inside the surface only.
        if (!neighboursOnSurface(p.frame2.depth, gt.x(), gt.y(), z2, 0.05)) continue;
        // The deformed elbow of frame 2 is where the ground truth says it is.
        blend_intensity_error.push_back(
            std::abs(bilinear(p.frame2.intensity, gt.x(), gt.y()) - p.frame1.intensity(x, y)));
        blend_depth_error.push_back(std::abs(bilinear(p.frame2.depth, gt.x(), gt.y()) - z2));
      }
      // Labels follow the larger weight: upper-arm pixels are nearer the upper arm's flow.
      if (off_line < 0.05) {
        if (id == upper.id) EXPECT_LE(alpha, 0.5 + 1e-3);
        if (id == fore.id) EXPECT_GE(alpha, 0.5 - 1e-3);
      }
    }
  std::printf("variant %d: %d of %d arm pixels in the blend zone\n", GetParam(), between, arm);
  EXPECT_GT(between, 60);
  EXPECT_LT(between, 0.6 * arm);
  ASSERT_GT(blend_visible, 0.8 * between);
  std::printf("blend zone: %zu of %d visible pixels inside the surface\n", blend_intensity_error.size(), blend_visible);
  EXPECT_GT(blend_intensity_error.size(), 0.7 * blend_visible);
  std::printf("blend zone: |dI| p50 %.4f p90 %.4f; |dZ| p50 %.2e m p90 %.2e m\n",
              percentile(blend_intensity_error, 0.5), percentile(blend_intensity_error, 0.9),
              percentile(blend_depth_error, 0.5), percentile(blend_depth_error, 0.9));
  EXPECT_LT(percentile(blend_intensity_error, 0.5), 0.01);
  EXPECT_LT(percentile(blend_intensity_error, 0.9), 0.05);
  EXPECT_LT(percentile(blend_depth_error, 0.9), 0.002);
}

TEST_P(SyntheticVariants, PartsHaveRealisticMotions) {
  const SyntheticPair p = renderSyntheticPair(optionsFor(GetParam()));
  std::map<int, std::vector<double>> displacement;
  for (std::size_t i = 0; i < p.gt_parts.pixelCount(); ++i) {
    const float* s = &p.gt_scene_flow.data[3 * i];
    if (std::isfinite(s[0]))
      displacement[p.gt_parts.data[i]].push_back(std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]));
  }
  std::set<int> ids;
  for (const SyntheticPart& part : p.parts) {
    EXPECT_TRUE(ids.insert(part.id).second) << "duplicate id " << part.id;
    if (part.id == 0 && GetParam() != 2) continue;
    const double angle = rotationAngle(se3Exp(part.twist)) * 180 / M_PI;
    const double median = percentile(displacement[part.id], 0.5);
    std::printf("variant %d part %d %s: rotation %.2f deg, median displacement %.1f mm\n", GetParam(), part.id,
                part.name.c_str(), angle, 1e3 * median);
    EXPECT_GT(angle, 0.9) << part.name;
    EXPECT_LT(angle, 4.5) << part.name;
    EXPECT_GT(median, 0.01) << part.name;
    EXPECT_LT(median, 0.08) << part.name;
  }
}

// Every variant there is (InvalidOptionsThrow checks that the next index is refused).
INSTANTIATE_TEST_SUITE_P(AllVariants, SyntheticVariants, ::testing::Range(0, syntheticVariantCount()));

TEST(SyntheticSequence, MotionsExplainConsecutiveFrames) {
  // Variant 2 (moving camera) at a frame well inside the sequence: each pixel of frame t must be carried
  // onto frame t+1 by one of the published part motions; motions of another time step must not do so.
  const SyntheticSceneOptions o = optionsFor(2);
  const int t = 9;
  RgbdFrame f0, f1;
  ImageU8 c;
  Intrinsics K;
  renderSyntheticFrame(o, t, f0, c, K);
  renderSyntheticFrame(o, t + 1, f1, c, K);
  auto explainedFraction = [&](const std::vector<SyntheticPart>& motions) {
    std::vector<Eigen::Matrix4d> T;
    for (const SyntheticPart& m : motions) T.push_back(se3Exp(m.twist));
    int valid = 0, explained = 0;
    for (int y = 0; y < f0.height(); ++y)
      for (int x = 0; x < f0.width(); ++x) {
        const float z = f0.depth(x, y);
        if (!isValidDepth(z)) continue;
        ++valid;
        const Eigen::Vector3d P = backProject(K, x, y, z);
        for (const Eigen::Matrix4d& M : T) {
          const Eigen::Vector3d P2 = transform(M, P);
          const Eigen::Vector2d x2 = project(K, P2);
          const double i2 = bilinear(f1.intensity, x2.x(), x2.y()), z2 = bilinear(f1.depth, x2.x(), x2.y());
          if (std::abs(i2 - f0.intensity(x, y)) < 0.04 && std::abs(z2 - P2.z()) < 0.01) {
            ++explained;
            break;
          }
        }
      }
    return double(explained) / valid;
  };
  const double right = explainedFraction(syntheticSequenceMotions(o, t));
  const double wrong = explainedFraction(syntheticSequenceMotions(o, 0));
  std::printf("pixels explained by the motions of step %d: %.3f; by those of step 0: %.3f\n", t, right, wrong);
  EXPECT_GT(right, 0.9);
  EXPECT_LT(wrong, right - 0.2);
}

TEST(SyntheticSequence, ObjectsStayInView) {
  for (int variant : {0, 1}) {  // static background: the farthest depth seen at a pixel is the room
    const SyntheticSceneOptions o = optionsFor(variant, 160, 120);
    std::vector<RgbdFrame> frames;
    for (int t = 0; t <= 30; t += 3) {
      RgbdFrame f;
      ImageU8 c;
      Intrinsics K;
      renderSyntheticFrame(o, t, f, c, K);
      frames.push_back(f);
    }
    std::vector<float> room(frames[0].depth.pixelCount(), 0.f);
    for (const RgbdFrame& f : frames)
      for (std::size_t i = 0; i < room.size(); ++i) room[i] = std::max(room[i], f.depth.data[i]);
    std::vector<int> object_pixels;
    for (const RgbdFrame& f : frames) {
      int n = 0;
      for (std::size_t i = 0; i < room.size(); ++i)
        n += isValidDepth(f.depth.data[i]) && f.depth.data[i] < room[i] - 0.05f;
      object_pixels.push_back(n);
    }
    for (std::size_t k = 0; k < object_pixels.size(); ++k)
      EXPECT_GT(object_pixels[k], 0.7 * object_pixels[0]) << "variant " << variant << " frame " << 3 * k;
    EXPECT_GT(object_pixels[0], 0.08 * room.size());
  }
}

TEST(SyntheticScene, HasAnInvalidDepthRegion) {
  for (int variant = 0; variant < syntheticVariantCount(); ++variant) {
    const SyntheticPair p = renderSyntheticPair(optionsFor(variant));
    int invalid = 0;
    for (float z : p.frame1.depth.data) invalid += !isValidDepth(z);
    EXPECT_GT(invalid, 500) << "variant " << variant;
    EXPECT_LT(invalid, 0.2 * p.frame1.depth.pixelCount()) << "variant " << variant;
  }
}

}  // namespace
}  // namespace mc_flow
