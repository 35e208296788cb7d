// The nodelet storm: valid pairs, then every bad case in a row, then valid pairs again. The nodelet never
// dies, warns for each bad case (throttled: each one counted in /diagnostics, the text on /rosout at most
// once per 5 s per problem, the next one saying how many were held back), the supported variants of the
// input are solved, and valid output resumes within two pairs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <nodelet/NodeletList.h>
#include <sensor_msgs/image_encodings.h>

#include "mc_flow/SegmentArray.h"
#include "mc_flow/core/image.h"
#include "rostest_common.h"

using mcflow_test::Collector;
using mcflow_test::diagnosticCount;
using mcflow_test::diagnosticValue;
using mcflow_test::RosoutWatcher;
using mcflow_test::SyntheticCamera;
using mcflow_test::waitFor;

namespace enc = sensor_msgs::image_encodings;

namespace {

constexpr int kWidth = 160, kHeight = 120;  // processed as they are (automatic downsampling: factor 1)

/// One published frame: the three messages, their stamp and the scene frame they show.
struct Triple {
  sensor_msgs::ImagePtr rgb, depth;
  sensor_msgs::CameraInfoPtr info;
  ros::Time stamp;
  int t = 0;
};

/// The nodelet's stamp text (sec.nsec).
std::string stampText(const ros::Time& t) {
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%u.%09u", t.sec, t.nsec);
  return buffer;
}

/// A copy scaled up by an integer factor (nearest pixel), e.g. a 4000x3000 camera from the 160x120 scene.
sensor_msgs::ImagePtr upscaled(const sensor_msgs::Image& in, int factor) {
  auto out = boost::make_shared<sensor_msgs::Image>();
  out->header = in.header;
  out->encoding = in.encoding;
  out->is_bigendian = in.is_bigendian;
  const std::size_t bytes = in.step / in.width;
  out->width = in.width * std::uint32_t(factor);
  out->height = in.height * std::uint32_t(factor);
  out->step = out->width * std::uint32_t(bytes);
  out->data.resize(std::size_t(out->step) * out->height);
  for (std::uint32_t y = 0; y < in.height; ++y) {
    std::uint8_t* row = &out->data[std::size_t(y) * factor * out->step];
    for (std::uint32_t x = 0; x < out->width; ++x)
      std::memcpy(row + x * bytes, &in.data[y * in.step + (x / factor) * bytes], bytes);
    for (int r = 1; r < factor; ++r) std::memcpy(row + std::size_t(r) * out->step, row, out->step);
  }
  return out;
}

/// camera_info of the same camera at `factor` times the resolution (pixel centres at integers).
sensor_msgs::CameraInfoPtr upscaled(const sensor_msgs::CameraInfo& in, int factor) {
  auto out = boost::make_shared<sensor_msgs::CameraInfo>(in);
  out->width *= std::uint32_t(factor);
  out->height *= std::uint32_t(factor);
  for (double* k : {&out->K[0], &out->K[4], &out->P[0], &out->P[5]}) *k *= factor;
  for (double* c : {&out->K[2], &out->K[5], &out->P[2], &out->P[6]}) *c = (*c + 0.5) * factor - 0.5;
  return out;
}

/// The rgb8 image in another supported colour encoding.
sensor_msgs::ImagePtr withEncoding(const sensor_msgs::Image& rgb8, const std::string& encoding) {
  auto out = boost::make_shared<sensor_msgs::Image>(rgb8);
  out->encoding = encoding;
  const std::size_t n = std::size_t(rgb8.width) * rgb8.height;
  const int channels = encoding == enc::RGBA8 || encoding == enc::BGRA8 ? 4 : encoding == enc::MONO8 ? 1 : 3;
  const int value_bytes = encoding == enc::MONO16 ? 2 : 1;
  out->step = rgb8.width * std::uint32_t(channels * value_bytes);
  out->data.assign(std::size_t(out->step) * rgb8.height, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* p = &rgb8.data[3 * i];
    const bool bgr = encoding == enc::BGR8 || encoding == enc::BGRA8;
    if (channels >= 3) {
      std::uint8_t* q = &out->data[i * std::size_t(channels)];
      q[0] = bgr ? p[2] : p[0];
      q[1] = p[1];
      q[2] = bgr ? p[0] : p[2];
      if (channels == 4) q[3] = 255;
    } else {
      const double grey = mc_flow::greyFromRgb(p[0], p[1], p[2]);
      if (value_bytes == 1) {
        out->data[i] = std::uint8_t(std::lround(grey));
      } else {
        const auto v = std::uint16_t(std::lround(grey * 257.0));
        std::memcpy(&out->data[2 * i], &v, 2);  // little-endian host, is_bigendian = 0
      }
    }
  }
  return out;
}

void fillDepth(sensor_msgs::Image& depth32, float value) {
  for (std::size_t i = 0; i + 4 <= depth32.data.size(); i += 4) std::memcpy(&depth32.data[i], &value, 4);
}

}  // namespace

class Storm : public ::testing::Test {
 protected:
  void SetUp() override {
    camera_ = std::make_unique<SyntheticCamera>(nh_, kWidth, kHeight);
    watcher_ = std::make_unique<RosoutWatcher>(nh_);
    segments_ = std::make_unique<Collector<mc_flow::SegmentArray>>(nh_, "/mc_flow/segments");
    outputs_info_ = std::make_unique<Collector<sensor_msgs::CameraInfo>>(nh_, "/mc_flow/camera_info");
    diagnostics_ = std::make_unique<Collector<diagnostic_msgs::DiagnosticArray>>(nh_, "/diagnostics");
    ASSERT_TRUE(waitFor([this] { return camera_->inputSubscribers() >= 3; }, 60.0)) << "the nodelet never subscribed";
    ASSERT_TRUE(waitFor([this] { return diagnosticCount(*diagnostics_, "pairs solved") >= 0; }, 30.0))
        << "no diagnostics";
  }

  /// The next valid frame of the synthetic scene, `step` seconds after the previous one.
  Triple valid(double step = 0.1) {
    stamp_ += ros::Duration(step);
    const int t = scene_frame_++ % 10;
    return {camera_->rgb(t, stamp_), camera_->depth(t, stamp_), camera_->info(stamp_), stamp_, t};
  }

  /// `f` at `factor` times the resolution: images and camera_info.
  static Triple upscaledTriple(const Triple& f, int factor) {
    return {upscaled(*f.rgb, factor), upscaled(*f.depth, factor), upscaled(*f.info, factor), f.stamp, f.t};
  }

  void publish(const Triple& f) { camera_->publish(f.rgb, f.depth, f.info); }

  bool solvedAt(const ros::Time& stamp) const {
    for (const auto& m : segments_->messages()) {
      if (m->header.stamp == stamp) return true;
    }
    return false;
  }

  /// A frame that starts a sequence: nothing to pair it with, so no output; the worker takes it at once.
  void startWith(const Triple& f) {
    publish(f);
    ros::WallDuration(0.5).sleep();
  }

  /// Publishes `f` and expects the pair ending at it to be solved (the previous frame was valid).
  void expectSolved(const Triple& f, const std::string& what) {
    publish(f);
    EXPECT_TRUE(waitFor([&] { return solvedAt(f.stamp); }, 60.0))
        << what << ": no pair solved ending at " << f.stamp << watcher_->dump();
  }

  long warnings(const std::string& kind) const {
    return std::max(0L, diagnosticCount(*diagnostics_, "warnings: " + kind));
  }

  /// Publishes `f` and expects one more warning of `kind` in /diagnostics (the throttle counts every
  /// warning, shown or held back) and a /rosout warning containing `text` (shown now or by an earlier case).
  void expectWarned(const Triple& f, const std::string& kind, const std::string& text) {
    const long before = warnings(kind);
    publish(f);
    EXPECT_TRUE(waitFor([&] { return warnings(kind) > before; }, 20.0))
        << "no '" << kind << "' warning counted for \"" << text << "\" (still " << before << ")" << watcher_->dump();
    EXPECT_TRUE(waitFor([&] { return watcher_->seen(text); }, 5.0))
        << "no warning containing \"" << text << "\" on /rosout" << watcher_->dump();
  }

  ros::NodeHandle nh_;
  std::unique_ptr<SyntheticCamera> camera_;
  std::unique_ptr<RosoutWatcher> watcher_;
  std::unique_ptr<Collector<mc_flow::SegmentArray>> segments_;
  std::unique_ptr<Collector<sensor_msgs::CameraInfo>> outputs_info_;
  std::unique_ptr<Collector<diagnostic_msgs::DiagnosticArray>> diagnostics_;
  ros::Time stamp_{6000.0};
  int scene_frame_ = 0;
};

TEST_F(Storm, EveryBadCaseWarnsAndValidOutputResumes) {
  const ros::WallTime started = ros::WallTime::now();
  // ---- Valid pairs.
  startWith(valid());
  expectSolved(valid(), "valid pair 1");
  expectSolved(valid(), "valid pair 2");
  double fx = 0;
  ASSERT_TRUE(waitFor([&] { return outputs_info_->count() > 0; }, 10.0)) << "no ~camera_info output";
  fx = outputs_info_->messages().back()->K[0];

  // ---- Every supported encoding is solved like rgb8 / 32FC1.
  for (const std::string& encoding : {enc::BGR8, enc::RGBA8, enc::BGRA8, enc::MONO8, enc::MONO16}) {
    Triple f = valid();
    f.rgb = withEncoding(*f.rgb, encoding);
    expectSolved(f, "colour " + encoding);
  }
  {
    Triple f = valid();
    f.depth = camera_->depth(f.t, f.stamp, "16UC1");
    expectSolved(f, "depth 16UC1");
  }

  // ---- An unsupported encoding, colour and depth.
  {
    Triple f = valid();
    f.rgb->encoding = "yuv422";
    expectWarned(f, "encoding", "unsupported colour encoding 'yuv422'");
    f = valid();
    f.depth->encoding = "8UC4";
    expectWarned(f, "encoding", "unsupported depth encoding '8UC4'");
  }

  // ---- NaN, infinite and negative depth: such pixels have no depth; a frame where no pixel has one is
  // skipped, and the same problem again within 5 s is counted, not shown.
  {
    Triple f = valid();
    const float values[4] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                             -std::numeric_limits<float>::infinity(), -1.5f};
    for (std::uint32_t y = 0; y < f.depth->height; ++y) {
      for (std::uint32_t x = 0; x < f.depth->width / 2; ++x) {  // the left half: every kind in bands of rows
        std::memcpy(&f.depth->data[y * f.depth->step + 4 * x], &values[(y / 8) % 4], 4);
      }
    }
    expectSolved(f, "depth with NaN, inf, -inf and negative pixels");
    const std::string no_valid = "(32FC1, 160x120) has no valid pixel";
    const long before = warnings("depth");
    const int shown_before = watcher_->count(no_valid);
    const ros::WallTime cases_start = ros::WallTime::now();
    for (float v : {values[0], values[1], values[2], values[3], 0.f}) {
      f = valid();
      fillDepth(*f.depth, v);
      expectWarned(f, "depth", no_valid);
    }
    EXPECT_EQ(warnings("depth"), before + 5);
    // Shown at most once per 5 s: one line, and one more per 5 s the five cases took (about 1 s each).
    const int allowed = 1 + int((ros::WallTime::now() - cases_start).toSec() / 5.0);
    EXPECT_LE(watcher_->count(no_valid) - shown_before, allowed) << "not throttled:" << watcher_->dump();
    f = valid();
    f.depth = camera_->depth(f.t, f.stamp, "16UC1");
    std::fill(f.depth->data.begin(), f.depth->data.end(), 0);
    expectWarned(f, "depth", "(16UC1, 160x120) has no valid pixel");
  }

  // ---- 1x1 images.
  {
    Triple f = valid();
    f.rgb->width = f.rgb->height = f.depth->width = f.depth->height = f.info->width = f.info->height = 1;
    f.rgb->step = 3;
    f.rgb->data.resize(3);
    f.depth->step = 4;
    f.depth->data.resize(4);
    fillDepth(*f.depth, 1.0f);
    expectWarned(f, "size", "processing size 1x1 (RGB 1x1 / downsample 1) is too small");
  }

  // ---- 4000x3000: a new sequence at the new size (warned), solved at 250x187 (automatic downsampling 16);
  // back at 160x120 another new sequence. (The warning names the processing sizes: the nodelet hands the
  // pipeline frames it has already downsampled.)
  {
    expectWarned(upscaledTriple(valid(), 25), "reset",
                 "the input changed from 'synthetic_rgb_optical_frame' 160x120 to");
    const ros::WallTime first_reset = ros::WallTime::now();
    const Triple big = upscaledTriple(valid(), 25);
    expectSolved(big, "4000x3000");
    EXPECT_TRUE(waitFor(
        [&] {
          for (const auto& m : outputs_info_->messages()) {
            if (m->header.stamp == big.stamp) return m->width == 250 && m->height == 187;
          }
          return false;
        },
        10.0))
        << "the 4000x3000 pair was not processed at 250x187";
    // The way back is a reset of the same kind: within the throttle's 5 s it would be counted but held back,
    // so that /rosout shows it only once the period has passed since the first one.
    const double since_first = (ros::WallTime::now() - first_reset).toSec();
    if (since_first < 5.5) ros::WallDuration(5.5 - since_first).sleep();
    expectWarned(valid(), "reset", "to 'synthetic_rgb_optical_frame' 160x120: starting a new sequence");
  }

  // ---- Colour and depth sizes: registered depth of the same aspect is resampled (solved); another aspect
  // means the depth is not registered to the colour camera (skipped).
  {
    Triple f = valid();
    f.depth = upscaled(*f.depth, 2);
    expectSolved(f, "depth 320x240 with colour 160x120");
    f = valid();
    f.depth->height = 90;
    f.depth->data.resize(std::size_t(f.depth->step) * f.depth->height);
    expectWarned(f, "size", "RGB 160x120 and depth 160x90 have different aspect ratios");
  }

  // ---- camera_info: P all zero means "use K" (solved); zero P and K, or a NaN in P: skipped.
  {
    Triple f = valid();
    f.info->P.fill(0.0);
    expectSolved(f, "camera_info with P all zero and a valid K");
    f = valid();
    f.info->P.fill(0.0);
    f.info->K.fill(0.0);
    expectWarned(f, "intrinsics", "unusable intrinsics (fx=0, fy=0 from K, P being all zero)");
    f = valid();
    f.info->P[0] = std::numeric_limits<double>::quiet_NaN();
    expectWarned(f, "intrinsics", "camera_info has a NaN or infinite entry");
  }

  // ---- Stamps repeating: held back before the synchroniser (one warning per topic); going back: the
  // synchroniser restarts and a new sequence starts, which the next frame continues.
  {
    const Triple f = valid();
    expectSolved(f, "a valid pair after the skipped frames");
    const Triple repeat{camera_->rgb(0, f.stamp), camera_->depth(0, f.stamp), camera_->info(f.stamp), f.stamp, 0};
    const long held_before = warnings("input_stamp");
    expectWarned(
        repeat, "input_stamp",
        "stamp " + stampText(f.stamp) + " repeats the previous message's: message held back from the synchroniser");
    EXPECT_TRUE(waitFor([&] { return warnings("input_stamp") >= held_before + 3; }, 10.0))
        << "not every topic's repeated stamp was counted" << watcher_->dump();
    stamp_ = f.stamp - ros::Duration(5.0);
    expectWarned(valid(), "reset", "the stamp went back by 4.9");
    EXPECT_TRUE(watcher_->seen(": restarting the synchroniser")) << watcher_->dump();
    expectSolved(valid(), "the pair after the stamps went back");
  }

  // ---- A burst of 200 frames at 100 Hz: frames that arrive during a solve are dropped and counted.
  {
    const std::string dropped_key = "frames dropped (arrived while solving)";
    const long dropped_before = diagnosticCount(*diagnostics_, dropped_key);
    const long synced_before = diagnosticCount(*diagnostics_, "frames synchronised");
    std::vector<Triple> burst;
    for (int i = 0; i < 200; ++i) burst.push_back(valid(0.01));  // rendered beforehand: publishing keeps the rate
    for (const Triple& f : burst) {
      publish(f);
      ros::WallDuration(0.01).sleep();
    }
    const ros::Time first = burst.front().stamp;
    auto solvedInBurst = [&] {
      for (const auto& m : segments_->messages()) {
        if (m->header.stamp > first && m->header.stamp <= burst.back().stamp) return true;
      }
      return false;
    };
    EXPECT_TRUE(waitFor(solvedInBurst, 60.0)) << "nothing solved during the burst" << watcher_->dump();
    // Most of the burst reaches the synchroniser (a loaded machine may lose a few before the callbacks),
    // and what arrived during a solve is counted as dropped.
    EXPECT_TRUE(
        waitFor([&] { return diagnosticCount(*diagnostics_, "frames synchronised") >= synced_before + 100; }, 20.0))
        << "synchronised " << synced_before << " before the burst, "
        << diagnosticValue(*diagnostics_, "frames synchronised") << " after";
    EXPECT_TRUE(waitFor([&] { return diagnosticCount(*diagnostics_, dropped_key) > dropped_before; }, 20.0))
        << "drops not counted: " << diagnosticValue(*diagnostics_, dropped_key);
    // Settled: the last frame waiting for the worker has been solved.
    std::size_t count = 0;
    while (segments_->count() != count) {
      count = segments_->count();
      ros::WallDuration(1.5).sleep();
    }
  }

  // ---- A camera_info for another resolution than the images (a binning camera): the intrinsics are
  // rescaled to the images, so the output intrinsics do not change.
  {
    Triple f = valid();
    f.info = upscaled(*f.info, 2);
    expectSolved(f, "camera_info of 320x240 with 160x120 images");
    EXPECT_TRUE(waitFor(
        [&] {
          for (const auto& m : outputs_info_->messages()) {
            if (m->header.stamp == f.stamp) return std::abs(m->K[0] - fx) < 1e-9 && m->width == 160;
          }
          return false;
        },
        10.0))
        << "intrinsics not rescaled to the images (fx " << fx << " before)";
  }

  // ---- The stream changes resolution (camera_info and images, e.g. a driver switched to 320x240): a new
  // sequence (warned), the next pair solved at the new size.
  {
    expectWarned(upscaledTriple(valid(), 2), "reset", "160x120 to 'synthetic_rgb_optical_frame' 320x240");
    expectSolved(upscaledTriple(valid(), 2), "320x240");
  }

  // ---- The no-valid-depth problem again, more than 5 s after it was shown: its warning says how many
  // like it were held back.
  {
    Triple f = valid();
    fillDepth(*f.depth, std::numeric_limits<float>::quiet_NaN());
    expectWarned(f, "depth", "(32FC1, 160x120) has no valid pixel");
    EXPECT_TRUE(waitFor([&] { return watcher_->seen("more like this since the last such warning"); }, 10.0))
        << watcher_->dump();
  }

  // ---- Valid pairs again: output within two pairs (the first frame starts a sequence after the 320x240 ones).
  {
    startWith(valid());
    const Triple second = valid();
    publish(second);
    waitFor([&] { return solvedAt(second.stamp); }, 60.0);
    const Triple third = valid();
    publish(third);
    EXPECT_TRUE(waitFor([&] { return solvedAt(second.stamp) || solvedAt(third.stamp); }, 60.0))
        << "no output within two valid pairs after the storm" << watcher_->dump();
    EXPECT_TRUE(waitFor([&] { return solvedAt(third.stamp); }, 60.0)) << "valid output did not continue";
  }

  // ---- The nodelet never died: its manager still runs it, and nothing escaped as an unexpected error.
  nodelet::NodeletList list;
  ASSERT_TRUE(ros::service::call("/manager/list", list)) << "the nodelet manager does not answer";
  EXPECT_NE(std::find(list.response.nodelets.begin(), list.response.nodelets.end(), "/mc_flow"),
            list.response.nodelets.end());
  EXPECT_FALSE(watcher_->seen("unexpected error")) << watcher_->dump();
  std::printf("storm: %.0f s wall; pairs solved %s, frames skipped %s, dropped %s, warnings shown %zu\n",
              (ros::WallTime::now() - started).toSec(), diagnosticValue(*diagnostics_, "pairs solved").c_str(),
              diagnosticValue(*diagnostics_, "frames skipped (bad input)").c_str(),
              diagnosticValue(*diagnostics_, "frames dropped (arrived while solving)").c_str(), watcher_->all().size());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "mc_flow_storm_test");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  spinner.stop();
  return result;
}
