// Message conversions without a running node: input frames, intrinsics, and every output message.
#include <gtest/gtest.h>

#include <any>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include "mc_flow/core/se3.h"
#include "mc_flow/core/palette.h"
#include "mc_flow/ros/conversions.h"

using mc_flow_ros::FrameInputError;
using mc_flow_ros::InputProblem;

namespace {

sensor_msgs::CameraInfo cameraInfo(int w, int h, double f = 500.0) {
  sensor_msgs::CameraInfo info;
  info.width = std::uint32_t(w);
  info.height = std::uint32_t(h);
  info.K = {f, 0, w / 2.0 - 0.5, 0, f, h / 2.0 - 0.5, 0, 0, 1};
  info.P = {f, 0, w / 2.0 - 0.5, 0, 0, f, h / 2.0 - 0.5, 0, 0, 0, 1, 0};
  return info;
}

/// A colour image whose pixel (x, y) has r = x, g = y, b = 200 (in the given encoding's channel order).
sensor_msgs::Image colourImage(int w, int h, const std::string& encoding) {
  sensor_msgs::Image image;
  image.header.frame_id = "cam";
  image.header.stamp = ros::Time(10, 500);
  image.width = std::uint32_t(w);
  image.height = std::uint32_t(h);
  image.encoding = encoding;
  const int channels = sensor_msgs::image_encodings::numChannels(encoding);
  const int depth_bytes = sensor_msgs::image_encodings::bitDepth(encoding) / 8;
  image.step = std::uint32_t(w * channels * depth_bytes);
  image.data.resize(std::size_t(image.step) * std::size_t(h));
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      std::uint8_t* p = &image.data[std::size_t(y) * image.step + std::size_t(x * channels * depth_bytes)];
      const std::uint8_t r = std::uint8_t(x), g = std::uint8_t(y), b = 200;
      if (encoding == "rgb8" || encoding == "rgba8") {
        p[0] = r;
        p[1] = g;
        p[2] = b;
      }
      if (encoding == "bgr8" || encoding == "bgra8") {
        p[0] = b;
        p[1] = g;
        p[2] = r;
      }
      if (encoding == "rgba8" || encoding == "bgra8") p[3] = 255;
      if (encoding == "mono8") p[0] = r;
      if (encoding == "mono16") {
        const std::uint16_t v = std::uint16_t(r * 257);
        std::memcpy(p, &v, 2);
      }
    }
  }
  return image;
}

sensor_msgs::Image depthImage(int w, int h, const std::string& encoding, float metres) {
  sensor_msgs::Image image;
  image.header.frame_id = "cam";
  image.width = std::uint32_t(w);
  image.height = std::uint32_t(h);
  image.encoding = encoding;
  const bool is16 = encoding == "16UC1";
  image.step = std::uint32_t(w * (is16 ? 2 : 4));
  image.data.resize(std::size_t(image.step) * std::size_t(h));
  for (int i = 0; i < w * h; ++i) {
    if (is16) {
      const std::uint16_t mm = std::uint16_t(std::lround(metres * 1000.f));
      std::memcpy(&image.data[std::size_t(2 * i)], &mm, 2);
    } else {
      std::memcpy(&image.data[std::size_t(4 * i)], &metres, 4);
    }
  }
  return image;
}

void setDepth(sensor_msgs::Image& image, int x, int y, float metres) {
  std::memcpy(&image.data[std::size_t(y) * image.step + std::size_t(4 * x)], &metres, 4);
}

}  // namespace

// The downsampling factor and rule are the core's (test/core/test_sequence.cpp: Downsampling.*).

TEST(Conversions, IntrinsicsFromPThenKAndRescaled) {
  sensor_msgs::CameraInfo info = cameraInfo(640, 480, 525.0);
  info.P[0] = 520.0;  // P wins over K
  mc_flow::Intrinsics K = mc_flow_ros::intrinsicsFromCameraInfo(info, 640, 480);
  EXPECT_DOUBLE_EQ(K.fx, 520.0);
  EXPECT_DOUBLE_EQ(K.fy, 525.0);
  EXPECT_DOUBLE_EQ(K.cx, 319.5);

  info.P.fill(0.0);  // some drivers fill K only
  K = mc_flow_ros::intrinsicsFromCameraInfo(info, 640, 480);
  EXPECT_DOUBLE_EQ(K.fx, 525.0);

  K = mc_flow_ros::intrinsicsFromCameraInfo(info, 320, 240);  // camera_info of the full-size image
  EXPECT_DOUBLE_EQ(K.fx, 262.5);
  EXPECT_DOUBLE_EQ(K.cx, (319.5 + 0.5) * 0.5 - 0.5);
}

TEST(Conversions, ZeroIntrinsicsAreRejectedNamingTheValue) {
  sensor_msgs::CameraInfo info;  // uncalibrated: all zero
  try {
    mc_flow_ros::intrinsicsFromCameraInfo(info, 640, 480);
    FAIL() << "zero intrinsics accepted";
  } catch (const FrameInputError& e) {
    EXPECT_EQ(e.problem, InputProblem::Intrinsics);
    EXPECT_NE(std::string(e.what()).find("fx=0"), std::string::npos) << e.what();
  }
}

TEST(Conversions, EveryColourEncodingGivesTheSameRgbAndIntensity) {
  for (const std::string encoding : {"rgb8", "bgr8", "rgba8", "bgra8"}) {
    const auto input = mc_flow_ros::toFrameInput(colourImage(64, 48, encoding), depthImage(64, 48, "16UC1", 1.5f),
                                                 cameraInfo(64, 48), 1);
    ASSERT_EQ(input.colour.type(), CV_8UC3) << encoding;
    const cv::Vec3b p = input.colour.at<cv::Vec3b>(7, 13);
    EXPECT_EQ(p[0], 13) << encoding;
    EXPECT_EQ(p[1], 7) << encoding;
    EXPECT_EQ(p[2], 200) << encoding;
    const double grey = (0.299 * 13 + 0.587 * 7 + 0.114 * 200) / 255.0;
    EXPECT_NEAR(input.frame.intensity(13, 7), grey, 1.0 / 255.0) << encoding;
    EXPECT_FLOAT_EQ(input.frame.depth(13, 7), 1.5f) << encoding;
    EXPECT_EQ(input.header.frame_id, "cam");
    EXPECT_EQ(input.header.stamp, ros::Time(10, 500));
  }
  for (const std::string encoding : {"mono8", "mono16"}) {
    const auto input = mc_flow_ros::toFrameInput(colourImage(64, 48, encoding), depthImage(64, 48, "32FC1", 2.0f),
                                                 cameraInfo(64, 48), 1);
    EXPECT_NEAR(input.frame.intensity(13, 7), 13.0 / 255.0, 1e-6) << encoding;
    EXPECT_EQ(input.colour.at<cv::Vec3b>(7, 13)[1], 13) << encoding;
  }
}

TEST(Conversions, DownsamplingScalesSizeAndIntrinsics) {
  const auto input = mc_flow_ros::toFrameInput(colourImage(64, 48, "rgb8"), depthImage(64, 48, "32FC1", 1.0f),
                                               cameraInfo(64, 48, 100.0), 2);
  EXPECT_EQ(input.frame.width(), 32);
  EXPECT_EQ(input.frame.height(), 24);
  EXPECT_EQ(input.colour.cols, 32);
  EXPECT_DOUBLE_EQ(input.K.fx, 50.0);
  EXPECT_DOUBLE_EQ(input.K.cx, (31.5 + 0.5) / 2 - 0.5);
  EXPECT_EQ(input.downsample, 2);
  // Block (2x2) averaging of r = x: pixels 26, 27 -> 26.5.
  EXPECT_NEAR(input.colour.at<cv::Vec3b>(3, 13)[0], 26.5, 0.6);
}

TEST(Conversions, AStreamFrameCarriesTheFrameInputAndAPairContextFindsItAgain) {
  auto previous = mc_flow_ros::toFrameInput(colourImage(64, 48, "rgb8"), depthImage(64, 48, "32FC1", 1.0f),
                                            cameraInfo(64, 48, 100.0), 2);
  previous.header.stamp = ros::Time(12.5);
  previous.header.frame_id = "camera_rgb_optical_frame";
  const mc_flow::StreamFrame frame = mc_flow_ros::toStreamFrame(previous);
  EXPECT_EQ(frame.frame.width(), 32);
  EXPECT_EQ(frame.frame.depth.data, previous.frame.depth.data);
  EXPECT_DOUBLE_EQ(frame.K.fx, previous.K.fx);
  EXPECT_DOUBLE_EQ(frame.stamp, 12.5);
  EXPECT_EQ(frame.source, "camera_rgb_optical_frame");
  EXPECT_FALSE(frame.camera_pose_prior);
  EXPECT_EQ(std::any_cast<const mc_flow_ros::FrameInput&>(frame.extra).colour.cols, 32);

  mc_flow_ros::FrameInput current = previous;
  current.header.stamp = ros::Time(12.6);
  mc_flow::PreparedFrame first, second;
  first.extra = previous;
  second.extra = current;
  mc_flow::SequenceStep step;
  step.first = &first;
  step.second = &second;
  step.world_velocities.resize(2);
  const mc_flow_ros::PairContext pair = mc_flow_ros::pairContext(step, 4.5);
  EXPECT_EQ(pair.previous, &std::any_cast<const mc_flow_ros::FrameInput&>(first.extra));
  EXPECT_EQ(pair.current, &std::any_cast<const mc_flow_ros::FrameInput&>(second.extra));
  EXPECT_EQ(pair.header.stamp, ros::Time(12.6));
  EXPECT_EQ(pair.header.frame_id, "camera_rgb_optical_frame");
  EXPECT_EQ(pair.previous_stamp, ros::Time(12.5));
  EXPECT_NEAR(pair.interval(), 0.1, 1e-9);
  EXPECT_DOUBLE_EQ(pair.solve_time_ms, 4.5);
  EXPECT_EQ(pair.world, &step.world_velocities);
  EXPECT_EQ(pair.previous_frame, &first.frame) << "the outputs read the first frame where the pipeline keeps it";
}

TEST(Conversions, DepthDownsamplingDoesNotAverageAcrossEdges) {
  auto depth = depthImage(32, 32, "32FC1", 1.0f);
  setDepth(depth, 0, 0, 3.0f);           // block (0,0): 3, 1, 1, 1 -> 1 (the far sample is another surface)
  setDepth(depth, 2, 0, std::nanf(""));  // block (1,0): NaN, 1, 1, 1 -> 1
  setDepth(depth, 4, 0, 1.02f);          // block (2,0): 1.02 is the same surface: averaged in
  // The core's rule (mc_flow::downsampleFrame, as the pyramid and `mcflow run-seq`): neighbours within
  // depth_downsample_range of the block's median, [1 3 3 1] weights.
  const auto input = mc_flow_ros::toFrameInput(colourImage(32, 32, "rgb8"), depth, cameraInfo(32, 32), 2);
  EXPECT_FLOAT_EQ(input.frame.depth(0, 0), 1.0f);
  EXPECT_NEAR(input.frame.depth(1, 0), 1.0f, 0.002f) << "the NaN is left out (the 4x4 window reaches the 1.02)";
  EXPECT_GT(input.frame.depth(2, 0), 1.0f);
  EXPECT_LT(input.frame.depth(2, 0), 1.01f);
}

TEST(Conversions, InvalidDepthBecomesZero) {
  auto depth = depthImage(32, 24, "32FC1", 1.0f);
  setDepth(depth, 5, 5, std::nanf(""));
  setDepth(depth, 6, 5, -1.f);
  const auto input = mc_flow_ros::toFrameInput(colourImage(32, 24, "rgb8"), depth, cameraInfo(32, 24), 1);
  EXPECT_EQ(input.frame.depth(5, 5), 0.f);
  EXPECT_EQ(input.frame.depth(6, 5), 0.f);
  EXPECT_EQ(input.valid_depth, 32 * 24 - 2);
}

TEST(Conversions, SmallerRegisteredDepthOfTheSameAspectIsResampled) {
  const auto input =
      mc_flow_ros::toFrameInput(colourImage(64, 48, "rgb8"), depthImage(32, 24, "16UC1", 0.8f), cameraInfo(64, 48), 1);
  EXPECT_EQ(input.frame.depth.width, 64);
  EXPECT_FLOAT_EQ(input.frame.depth(63, 47), 0.8f);
}

TEST(Conversions, BadInputsThrowTheirKindNamingTheValue) {
  auto expectProblem = [](const sensor_msgs::Image& rgb, const sensor_msgs::Image& depth,
                          const sensor_msgs::CameraInfo& info, InputProblem problem, const std::string& named) {
    try {
      mc_flow_ros::toFrameInput(rgb, depth, info, 1);
      ADD_FAILURE() << "accepted; expected a message naming " << named;
    } catch (const FrameInputError& e) {
      EXPECT_EQ(int(e.problem), int(problem)) << e.what();
      EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
    }
  };
  auto yuv = colourImage(64, 48, "rgb8");
  yuv.encoding = "yuv422";
  expectProblem(yuv, depthImage(64, 48, "16UC1", 1.f), cameraInfo(64, 48), InputProblem::Encoding, "yuv422");
  auto depth8 = depthImage(64, 48, "16UC1", 1.f);
  depth8.encoding = "mono8";
  expectProblem(colourImage(64, 48, "rgb8"), depth8, cameraInfo(64, 48), InputProblem::Encoding, "mono8");
  expectProblem(colourImage(64, 48, "rgb8"), depthImage(64, 36, "16UC1", 1.f), cameraInfo(64, 48), InputProblem::Size,
                "64x36");
  expectProblem(colourImage(64, 48, "rgb8"), depthImage(64, 48, "16UC1", 0.f), cameraInfo(64, 48), InputProblem::Depth,
                "no valid pixel");
  expectProblem(colourImage(64, 48, "rgb8"), depthImage(64, 48, "32FC1", std::nanf("")), cameraInfo(64, 48),
                InputProblem::Depth, "no valid pixel");
  expectProblem(colourImage(64, 48, "rgb8"), depthImage(64, 48, "16UC1", 1.f), sensor_msgs::CameraInfo(),
                InputProblem::Intrinsics, "calibrated");
}

// ---------------------------------------------------------------- outputs from a hand-made Result

namespace {

struct Fixture {
  mc_flow::Result result;
  mc_flow_ros::FrameInput previous, current;
  mc_flow_ros::PairContext pair;
};

/// 4x3 result: segment id 7 = left half (static), id 9 = right half (moving +x 2 cm per interval);
/// pixel (0, 0) is an outlier without depth.
Fixture makeFixture() {
  Fixture f;
  const int w = 4, h = 3;
  mc_flow::Result& r = f.result;
  r.width = w;
  r.height = h;
  r.intrinsics = {2.0, 2.0, 1.5, 1.0};
  mc_flow::Segment s1, s2;
  s1.id = 7;  // persistent ids, as a stream gives them
  s2.id = 9;
  s2.twist << 0.02, 0, 0, 0, 0, 0.01;
  s2.transform = mc_flow::se3Exp(s2.twist);
  s1.support = 5;
  s2.support = 6;
  s2.centroid = Eigen::Vector3d(0.5, 0, 2);
  r.segments = {s1, s2};
  r.soft_labels = mc_flow::SoftLabels(w, h, 3, 0.f);
  r.labels = mc_flow::ImageI32(w, h, 1, 0);
  r.occlusion = mc_flow::ImageU8(w, h, 1, 0);
  r.scene_flow = mc_flow::ImageF(w, h, 3, 0.f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int label = x < 2 ? 1 : 2;
      r.labels(x, y) = label == 1 ? 7 : 9;
      r.soft_labels.at(label - 1, x, y) = 0.75f;
      r.soft_labels.at(2, x, y) = 0.25f;
      if (label == 2) r.scene_flow(x, y, 0) = 0.02f;
    }
  r.labels(0, 0) = 0;
  r.occlusion(3, 2) = 255;
  r.scene_flow(0, 0, 0) = std::nanf("");

  f.previous.frame.depth = mc_flow::ImageF(w, h, 1, 2.0f);
  f.previous.frame.depth(0, 0) = 0.f;
  f.previous.frame.intensity = mc_flow::ImageF(w, h, 1, 0.5f);
  f.previous.colour = cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 20, 30));
  f.previous.K = r.intrinsics;
  f.current = f.previous;
  f.pair.header.frame_id = "camera_rgb_optical_frame";
  f.pair.header.stamp = ros::Time(100, 200000000);
  f.pair.previous_stamp = ros::Time(100, 100000000);  // 0.1 s interval
  f.pair.previous = &f.previous;
  f.pair.current = &f.current;
  f.pair.solve_time_ms = 12.5;
  return f;
}

// A pooled message is handed out again only when nobody else holds it, and is then refilled to the same bytes as a
// new message: for every image output and the cloud, across pairs whose contents differ.
TEST(Conversions, PooledMessagesAreReusedOnceReleasedAndEqualNewOnes) {
  mc_flow_ros::ImagePool pool;
  auto held = pool.take();
  auto second = pool.take();
  EXPECT_NE(held, second) << "a message someone holds is not handed out again";
  const sensor_msgs::Image* released = second.get();
  second.reset();
  EXPECT_EQ(pool.take().get(), released) << "a released message is reused";
  for (int k = 0; k < 5; ++k) pool.take();  // each released at once: the same message again
  EXPECT_EQ(pool.size(), 2u);

  Fixture f = makeFixture();
  mc_flow_ros::ImagePool soft, labels, occlusion, segmentation, moving;
  mc_flow_ros::CloudPool cloud;
  const std::vector<mc_flow::WorldVelocity> world(f.result.segments.size());
  for (int pair = 0; pair < 3; ++pair) {
    SCOPED_TRACE("pair " + std::to_string(pair));
    // Another pair: other values (the pooled messages hold the last pair's).
    f.result.soft_labels.at(0, 1, 1) = 0.1f * float(pair + 1);
    f.result.labels(2, 2) = pair == 1 ? 0 : 9;
    f.result.occlusion(1, 0) = pair == 2 ? 255 : 0;
    f.pair.header.stamp = ros::Time(20.0 + pair);
    auto same = [](const sensor_msgs::ImagePtr& a, const sensor_msgs::ImagePtr& b) {
      return a->header.stamp == b->header.stamp && a->encoding == b->encoding && a->width == b->width &&
             a->height == b->height && a->step == b->step && a->data == b->data;
    };
    EXPECT_TRUE(same(mc_flow_ros::makeSoftLabelsImage(f.result, f.pair, &soft),
                     mc_flow_ros::makeSoftLabelsImage(f.result, f.pair)));
    EXPECT_TRUE(
        same(mc_flow_ros::makeLabelsImage(f.result, f.pair, &labels), mc_flow_ros::makeLabelsImage(f.result, f.pair)));
    EXPECT_TRUE(same(mc_flow_ros::makeOcclusionImage(f.result, f.pair, &occlusion),
                     mc_flow_ros::makeOcclusionImage(f.result, f.pair)));
    EXPECT_TRUE(same(mc_flow_ros::makeMovingMaskImage(f.result, world, f.pair, &moving),
                     mc_flow_ros::makeMovingMaskImage(f.result, world, f.pair)));
    const cv::Mat picture = mc_flow_ros::segmentationPicture(f.result, f.pair, 0.5);
    const auto pooled_picture = mc_flow_ros::makeSegmentationImage(picture, f.pair, &segmentation);
    const auto bridged = cv_bridge::CvImage(f.pair.header, "rgb8", picture).toImageMsg();
    EXPECT_TRUE(same(pooled_picture, bridged)) << "the message cv_bridge makes";
    const auto a = mc_flow_ros::makeSceneFlowCloud(f.result, f.pair, mc_flow_ros::CloudColour::Segment, &cloud);
    const auto b = mc_flow_ros::makeSceneFlowCloud(f.result, f.pair);
    EXPECT_EQ(a->data, b->data);
    EXPECT_EQ(a->fields.size(), b->fields.size());
    EXPECT_EQ(a->point_step, b->point_step);
    EXPECT_EQ(a->row_step, b->row_step);
    EXPECT_EQ(a->width, b->width);
    EXPECT_EQ(a->height, b->height);
    EXPECT_EQ(a->header.stamp, b->header.stamp);
  }
  EXPECT_EQ(cloud.size(), 1u) << "every pair's cloud was released before the next: one message served all";
}

}  // namespace

TEST(Conversions, SegmentArrayCarriesRatesTransformsIdsAndStamps) {
  const Fixture f = makeFixture();
  const mc_flow::SegmentArray msg = mc_flow_ros::makeSegmentArray(f.result, f.pair);
  EXPECT_EQ(msg.header.stamp, f.pair.header.stamp);
  EXPECT_EQ(msg.header.frame_id, "camera_rgb_optical_frame");
  EXPECT_EQ(msg.previous_stamp, f.pair.previous_stamp);
  ASSERT_EQ(msg.segments.size(), 2u);
  EXPECT_EQ(msg.segments[0].id, 7u);
  EXPECT_EQ(msg.segments[1].id, 9u);
  EXPECT_NEAR(msg.segments[1].twist.linear.x, 0.2, 1e-9);   // 0.02 m / 0.1 s
  EXPECT_NEAR(msg.segments[1].twist.angular.z, 0.1, 1e-9);  // 0.01 rad / 0.1 s
  EXPECT_NEAR(msg.segments[1].transform.translation.x, f.result.segments[1].transform(0, 3), 1e-12);
  EXPECT_NEAR(msg.segments[1].transform.rotation.z, std::sin(0.005), 1e-9);
  EXPECT_NEAR(msg.segments[1].transform.rotation.w, std::cos(0.005), 1e-9);
  EXPECT_DOUBLE_EQ(msg.segments[1].support, 6.0);
  EXPECT_DOUBLE_EQ(msg.segments[1].centroid.z, 2.0);
  const auto c = mc_flow::colourForId(9);
  EXPECT_FLOAT_EQ(msg.segments[1].color.r, c.r / 255.f);
  EXPECT_EQ(msg.width, 4u);
  EXPECT_DOUBLE_EQ(msg.outlier_support, 1.0);
  EXPECT_DOUBLE_EQ(msg.solve_time_ms, 12.5);
  EXPECT_EQ(msg.start, "cold");  // the fixture's Result: the default start
  EXPECT_EQ(msg.start_note, "");
}

TEST(Conversions, SegmentArrayCarriesTheStartKind) {
  Fixture f = makeFixture();
  f.result.start = mc_flow::StartKind::Warm;
  EXPECT_EQ(mc_flow_ros::makeSegmentArray(f.result, f.pair).start, "warm");
  f.result.start = mc_flow::StartKind::ColdFallback;
  f.result.start_note = "the carried segments cover 12 % of the valid pixels";
  const mc_flow::SegmentArray msg = mc_flow_ros::makeSegmentArray(f.result, f.pair);
  EXPECT_EQ(msg.start, "cold_fallback");
  EXPECT_EQ(msg.start_note, f.result.start_note);
}

TEST(Conversions, SegmentArraySaysWhyTheWorldIsTheWorld) {
  Fixture f = makeFixture();
  EXPECT_EQ(mc_flow_ros::makeSegmentArray(f.result, f.pair).world_chosen_by, "");  // no world found
  f.result.world.found = true;
  f.result.world.ids = {7};
  f.result.world.chosen_by = "prior";
  const mc_flow::SegmentArray msg = mc_flow_ros::makeSegmentArray(f.result, f.pair);
  EXPECT_EQ(msg.world_chosen_by, "prior");
}

TEST(Conversions, SoftLabelsImageIsLossless) {
  Fixture f = makeFixture();
  f.result.soft_labels.at(0, 1, 1) = 0.123456789f;
  const auto msg = mc_flow_ros::makeSoftLabelsImage(f.result, f.pair);
  EXPECT_EQ(msg->encoding, "32FC3");
  EXPECT_EQ(msg->width, 4u);
  EXPECT_EQ(msg->height, 3u);
  EXPECT_EQ(msg->step, 4u * 3u * 4u);
  EXPECT_EQ(msg->header.stamp, f.pair.header.stamp);
  const auto* data = reinterpret_cast<const float*>(msg->data.data());
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x)
      for (int c = 0; c < 3; ++c) EXPECT_EQ(data[(y * 4 + x) * 3 + c], f.result.soft_labels.at(c, x, y));
}

// A result of `planes` label planes (planes - 1 segments + the outlier) on an odd-sized frame: rows beyond one block
// of makeImageOutputs' 16, columns that leave a tail after the 8-pixel blocks; random labels, flow, occlusion and depth
// (some invalid: zero, NaN, infinite).
Fixture makeLargerFixture(int planes, unsigned seed) {
  Fixture f;
  const int w = 37, h = 21;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  mc_flow::Result& r = f.result;
  r.width = w;
  r.height = h;
  r.intrinsics = {30.0, 31.0, 18.2, 10.1};
  for (int i = 0; i + 1 < planes; ++i) {
    mc_flow::Segment s;
    s.id = 3 + 2 * i;
    r.segments.push_back(s);
  }
  r.world.ids = {3};
  r.soft_labels = mc_flow::SoftLabels(w, h, planes, 0.f);
  r.labels = mc_flow::ImageI32(w, h, 1, 0);
  r.occlusion = mc_flow::ImageU8(w, h, 1, 0);
  r.scene_flow = mc_flow::ImageF(w, h, 3, 0.f);
  f.previous.frame.depth = mc_flow::ImageF(w, h, 1, 0.f);
  f.previous.frame.intensity = mc_flow::ImageF(w, h, 1, 0.f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      for (int c = 0; c < planes; ++c) r.soft_labels.at(c, x, y) = unit(rng);
      const int segment = int(unit(rng) * float(planes));
      r.labels(x, y) = segment + 1 < planes ? r.segments[std::size_t(segment)].id : 0;
      r.occlusion(x, y) = unit(rng) < 0.2f ? 255 : 0;
      for (int c = 0; c < 3; ++c) r.scene_flow(x, y, c) = unit(rng) - 0.5f;
      const float draw = unit(rng);
      f.previous.frame.depth(x, y) = draw < 0.05f   ? 0.f
                                     : draw < 0.08f ? std::nanf("")
                                     : draw < 0.1f  ? std::numeric_limits<float>::infinity()
                                                    : 0.5f + 3.f * unit(rng);
      f.previous.frame.intensity(x, y) = unit(rng);
    }
  f.previous.colour = cv::Mat(h, w, CV_8UC3);
  cv::randu(f.previous.colour, 0, 255);
  f.previous.K = r.intrinsics;
  f.current = f.previous;
  f.pair.header.frame_id = "camera_rgb_optical_frame";
  f.pair.header.stamp = ros::Time(100, 200000000);
  f.pair.previous_stamp = ros::Time(100, 100000000);
  f.pair.previous = &f.previous;
  f.pair.current = &f.current;
  return f;
}

// Every plane count (the interleave takes 2-8 planes 8 pixels at a time where the CPU has AVX2, others one at a time):
// each pixel's channels are its planes' values, bit for bit.
TEST(Conversions, SoftLabelsOfEveryPlaneCountAreInterleavedExactly) {
  for (int planes = 1; planes <= 10; ++planes) {
    SCOPED_TRACE(std::to_string(planes) + " planes");
    const Fixture f = makeLargerFixture(planes, unsigned(planes));
    const auto msg = mc_flow_ros::makeSoftLabelsImage(f.result, f.pair);
    ASSERT_EQ(msg->encoding, "32FC" + std::to_string(planes));
    ASSERT_EQ(msg->data.size(), std::size_t(37 * 21 * planes) * sizeof(float));
    const auto* data = reinterpret_cast<const float*>(msg->data.data());
    int wrong = 0;
    for (int y = 0; y < 21; ++y)
      for (int x = 0; x < 37; ++x)
        for (int c = 0; c < planes; ++c) {
          const float expected = f.result.soft_labels.at(c, x, y);
          wrong += std::memcmp(&data[(y * 37 + x) * planes + c], &expected, sizeof expected) != 0;
        }
    EXPECT_EQ(wrong, 0);
  }
}

// The vectorised count takes the values mc_flow::isValidDepth takes: NaNs, infinities, zeros of both signs, negatives,
// denormals, the largest float.
TEST(Conversions, ValidDepthCountIsIsValidDepths) {
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<float> depth = {std::nanf(""),
                                    -std::nanf(""),
                                    inf,
                                    -inf,
                                    0.f,
                                    -0.f,
                                    -1.f,
                                    std::numeric_limits<float>::denorm_min(),
                                    -std::numeric_limits<float>::denorm_min(),
                                    std::numeric_limits<float>::max(),
                                    1.5f,
                                    1e-30f};
  int expected = 0;
  for (const float z : depth) expected += mc_flow::isValidDepth(z) ? 1 : 0;
  EXPECT_EQ(mc_flow_ros::countValidDepth(depth), expected);
  EXPECT_EQ(expected, 4);
}

// A range of pixels writes exactly its own floats (threads fill neighbouring ranges of one buffer): every plane count,
// ranges that start and end anywhere in an 8-pixel block or cover less than one, the buffer's last pixel included;
// every float outside the range keeps its sentinel, every one inside is the plane's value.
TEST(Conversions, SoftLabelRangesWriteExactlyTheirOwnFloats) {
  const float sentinel = -12345.f;
  for (int planes = 1; planes <= 10; ++planes) {
    SCOPED_TRACE(std::to_string(planes) + " planes");
    const Fixture f = makeLargerFixture(planes, unsigned(100 + planes));
    const mc_flow::SoftLabels& u = f.result.soft_labels;
    const std::size_t pixels = std::size_t(u.width) * std::size_t(u.height);
    int wrong = 0;
    for (const std::size_t begin : {std::size_t(0), std::size_t(1), std::size_t(5), std::size_t(13), pixels - 9})
      for (const std::size_t length : {std::size_t(1), std::size_t(3), std::size_t(7), std::size_t(8), std::size_t(9),
                                       std::size_t(16), std::size_t(21), std::size_t(37)}) {
        const std::size_t end = std::min(pixels, begin + length);
        std::vector<float> out(pixels * std::size_t(planes), sentinel);
        mc_flow_ros::interleaveSoftLabels(u, begin, end, out.data());
        for (std::size_t p = 0; p < pixels; ++p)
          for (int c = 0; c < planes; ++c) {
            const float got = out[p * std::size_t(planes) + std::size_t(c)];
            const bool inside = p >= begin && p < end;
            wrong += inside ? got != u.plane(c)[p] : got != sentinel;
          }
      }
    EXPECT_EQ(wrong, 0);
  }
}

// The cloud's points against their definitions on a frame with invalid depth and image colours: x y z the ray times
// the depth (NaN without depth), v the scene flow (NaN without depth), label the id, occluded 0/1, rgb the image's.
TEST(Conversions, SceneFlowCloudPointsFollowTheirDefinitionOnALargerFrame) {
  Fixture f = makeLargerFixture(4, 11);
  // A scene flow with a fourth channel: each pixel's first three are its flow.
  mc_flow::ImageF wide(f.result.width, f.result.height, 4, 9.f);
  for (int v = 0; v < f.result.height; ++v)
    for (int u = 0; u < f.result.width; ++u)
      for (int k = 0; k < 3; ++k) wide(u, v, k) = f.result.scene_flow(u, v, k);
  const mc_flow::ImageF three = f.result.scene_flow;
  for (const int channels : {3, 4}) {
    f.result.scene_flow = channels == 3 ? three : wide;
    for (const auto colour : {mc_flow_ros::CloudColour::Image, mc_flow_ros::CloudColour::Segment}) {
      const auto cloud = mc_flow_ros::makeSceneFlowCloud(f.result, f.pair, colour);
      sensor_msgs::PointCloud2ConstIterator<float> x(*cloud, "x"), vx(*cloud, "vx");
      sensor_msgs::PointCloud2ConstIterator<std::uint32_t> rgb(*cloud, "rgb"), label(*cloud, "label");
      sensor_msgs::PointCloud2ConstIterator<std::uint8_t> occluded(*cloud, "occluded");
      const mc_flow::Intrinsics& K = f.result.intrinsics;
      int wrong = 0;
      for (int v = 0; v < 21; ++v)
        for (int u = 0; u < 37; ++u, ++x, ++vx, ++rgb, ++label, ++occluded) {
          const float z = f.previous.frame.depth(u, v);
          const bool valid = std::isfinite(z) && z > 0.f;
          const float expected_xyz[3] = {float((u - K.cx) / K.fx * z), float((v - K.cy) / K.fy * z), z};
          for (int k = 0; k < 3; ++k) {
            wrong += valid ? x[k] != expected_xyz[k] : !std::isnan(x[k]);
            wrong += valid ? vx[k] != f.result.scene_flow(u, v, k) : !std::isnan(vx[k]);
          }
          const std::uint32_t id = std::uint32_t(f.result.labels(u, v));
          wrong += *label != id;
          wrong += *occluded != (f.result.occlusion(u, v) > 0 ? 1 : 0);
          const cv::Vec3b& p = f.previous.colour.at<cv::Vec3b>(v, u);
          const mc_flow::Rgb8 c = colour == mc_flow_ros::CloudColour::Image
                                      ? mc_flow::Rgb8{p[0], p[1], p[2]}
                                      : mc_flow::displayColour(id, f.result.world.ids);
          wrong += *rgb != ((std::uint32_t(c.r) << 16) | (std::uint32_t(c.g) << 8) | std::uint32_t(c.b));
        }
      EXPECT_EQ(wrong, 0) << (colour == mc_flow_ros::CloudColour::Image ? "image colours" : "segment colours") << ", "
                          << channels << " flow channels";
      // The padding after `occluded` is zero.
      for (std::size_t at = 33; at < cloud->data.size(); at += 36)
        ASSERT_EQ(cloud->data[at] | cloud->data[at + 1] | cloud->data[at + 2], 0) << "point " << at / 36;
    }
  }
}

// makeImageOutputs (the nodelet's path: the three large messages in one parallel region, from pools) gives the bytes
// of the make* functions, for every selection of them.
TEST(Conversions, ImageOutputsBuiltTogetherAreTheMessagesBuiltAlone) {
  const Fixture f = makeLargerFixture(6, 5);
  mc_flow_ros::ImagePool soft_pool, segmentation_pool;
  mc_flow_ros::CloudPool cloud_pool;
  for (int selection = 0; selection < 8; ++selection) {
    SCOPED_TRACE("selection " + std::to_string(selection));
    mc_flow_ros::ImageOutputRequest request;
    request.soft_labels = selection & 1;
    request.segmentation = selection & 2;
    request.scene_flow = selection & 4;
    request.segmentation_blend = 0.6;
    request.cloud_colour = mc_flow_ros::CloudColour::Image;
    request.soft_labels_pool = &soft_pool;
    request.segmentation_pool = &segmentation_pool;
    request.cloud_pool = &cloud_pool;
    const mc_flow_ros::ImageOutputs built = mc_flow_ros::makeImageOutputs(f.result, f.pair, request);
    ASSERT_EQ(bool(built.soft_labels), request.soft_labels);
    ASSERT_EQ(bool(built.segmentation), request.segmentation);
    ASSERT_EQ(bool(built.scene_flow), request.scene_flow);
    if (built.soft_labels) {
      const auto alone = mc_flow_ros::makeSoftLabelsImage(f.result, f.pair);
      EXPECT_EQ(built.soft_labels->data, alone->data);
      EXPECT_EQ(built.soft_labels->encoding, alone->encoding);
      EXPECT_EQ(built.soft_labels->step, alone->step);
    }
    if (built.segmentation) {
      const auto alone = mc_flow_ros::makeSegmentationImage(f.result, f.pair, 0.6);
      EXPECT_EQ(built.segmentation->data, alone->data);
      EXPECT_EQ(built.segmentation->encoding, alone->encoding);
    }
    if (built.scene_flow) {
      const auto alone = mc_flow_ros::makeSceneFlowCloud(f.result, f.pair, mc_flow_ros::CloudColour::Image);
      EXPECT_EQ(built.scene_flow->data, alone->data);
      EXPECT_EQ(built.scene_flow->row_step, alone->row_step);
      EXPECT_EQ(built.scene_flow->header.stamp, alone->header.stamp);
    }
  }
}

TEST(Conversions, LabelAndOcclusionImages) {
  const Fixture f = makeFixture();
  const auto labels = mc_flow_ros::makeLabelsImage(f.result, f.pair);
  EXPECT_EQ(labels->encoding, "mono16");
  const auto* ids = reinterpret_cast<const std::uint16_t*>(labels->data.data());
  EXPECT_EQ(ids[0], 0);      // outlier
  EXPECT_EQ(ids[1], 7);      // segment 1 -> id 7
  EXPECT_EQ(ids[4 + 3], 9);  // segment 2 -> id 9
  const auto occlusion = mc_flow_ros::makeOcclusionImage(f.result, f.pair);
  EXPECT_EQ(occlusion->encoding, "mono8");
  EXPECT_EQ(occlusion->data[2 * 4 + 3], 255);
  EXPECT_EQ(occlusion->data[0], 0);
  const auto segmentation =
      mc_flow_ros::makeSegmentationImage(mc_flow_ros::segmentationPicture(f.result, f.pair, 1.0), f.pair);
  EXPECT_EQ(segmentation->encoding, "rgb8");
  const auto c7 = mc_flow::colourForId(7), c0 = mc_flow::colourForId(0);
  EXPECT_NEAR(segmentation->data[(4 + 1) * 3], 0.75 * c7.r + 0.25 * c0.r, 1.0);  // soft blend of the labels
  // Rendered straight into the message (the nodelet's way, from a pool): the same message.
  mc_flow_ros::ImagePool pool;
  for (const double blend : {1.0, 0.6}) {
    const auto direct = mc_flow_ros::makeSegmentationImage(f.result, f.pair, blend, &pool);
    const auto copied =
        mc_flow_ros::makeSegmentationImage(mc_flow_ros::segmentationPicture(f.result, f.pair, blend), f.pair);
    EXPECT_EQ(direct->data, copied->data) << "blend " << blend;
    EXPECT_EQ(direct->encoding, copied->encoding);
    EXPECT_EQ(direct->step, copied->step);
    EXPECT_EQ(direct->width, copied->width);
    EXPECT_EQ(direct->height, copied->height);
    EXPECT_EQ(direct->header.stamp, copied->header.stamp);
  }
}

TEST(Conversions, SceneFlowCloudHasTheDocumentedFields) {
  const Fixture f = makeFixture();
  const auto cloud = mc_flow_ros::makeSceneFlowCloud(f.result, f.pair);
  EXPECT_EQ(cloud->width, 4u);
  EXPECT_EQ(cloud->height, 3u);
  EXPECT_FALSE(cloud->is_dense);
  EXPECT_EQ(cloud->header.frame_id, "camera_rgb_optical_frame");
  const std::vector<std::pair<std::string, int>> expected = {
      {"x", sensor_msgs::PointField::FLOAT32},     {"y", sensor_msgs::PointField::FLOAT32},
      {"z", sensor_msgs::PointField::FLOAT32},     {"rgb", sensor_msgs::PointField::FLOAT32},
      {"vx", sensor_msgs::PointField::FLOAT32},    {"vy", sensor_msgs::PointField::FLOAT32},
      {"vz", sensor_msgs::PointField::FLOAT32},    {"label", sensor_msgs::PointField::UINT32},
      {"occluded", sensor_msgs::PointField::UINT8}};
  ASSERT_EQ(cloud->fields.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(cloud->fields[i].name, expected[i].first);
    EXPECT_EQ(cloud->fields[i].datatype, expected[i].second);
  }
  // Points padded to 36 bytes, so every point's floats are 4-byte aligned (33 bytes of fields).
  EXPECT_EQ(cloud->fields.back().offset, 32u);
  EXPECT_EQ(cloud->point_step, 36u);
  EXPECT_EQ(cloud->row_step, 4u * 36u);
  EXPECT_EQ(cloud->data.size(), 12u * 36u);
  sensor_msgs::PointCloud2ConstIterator<float> x(*cloud, "x"), vx(*cloud, "vx");
  sensor_msgs::PointCloud2ConstIterator<std::uint32_t> label(*cloud, "label");
  sensor_msgs::PointCloud2ConstIterator<std::uint8_t> occluded(*cloud, "occluded");
  // Pixel (0, 0): no depth -> NaN point.
  EXPECT_TRUE(std::isnan(x[0]) && std::isnan(x[1]) && std::isnan(x[2]));
  EXPECT_TRUE(std::isnan(vx[0]));
  EXPECT_EQ(*label, 0u);
  // Pixel (3, 2): z = 2, x = (3 - 1.5) / 2 * 2 = 1.5, y = (2 - 1) / 2 * 2 = 1; moving segment, occluded.
  const int last = 11;
  x += last;
  vx += last;
  label += last;
  occluded += last;
  EXPECT_FLOAT_EQ(x[0], 1.5f);
  EXPECT_FLOAT_EQ(x[1], 1.0f);
  EXPECT_FLOAT_EQ(x[2], 2.0f);
  EXPECT_FLOAT_EQ(vx[0], 0.02f);
  EXPECT_FLOAT_EQ(vx[1], 0.0f);
  EXPECT_EQ(*label, 9u);
  EXPECT_EQ(*occluded, 1);
}

TEST(Conversions, SegmentTransformsFollowTheTracksOfTheSegmentsThatHaveOne) {
  const Fixture f = makeFixture();
  std::map<int, mc_flow::SegmentTrack> tracks;
  mc_flow::SegmentTrack& track = tracks[9];
  track.pose = mc_flow::se3Exp(f.result.segments[1].twist);
  track.origin = Eigen::Vector3d(0.5, -0.25, 2.0);
  tracks[3];  // a track without a segment in this pair: no frame
  const auto transforms = mc_flow_ros::makeSegmentTransforms(f.result, tracks, f.pair, "seg_");
  ASSERT_EQ(transforms.size(), 1u) << "id 7 has no track, id 3 no segment";
  const geometry_msgs::TransformStamped& t = transforms[0];
  EXPECT_EQ(t.header.frame_id, "camera_rgb_optical_frame");
  EXPECT_EQ(t.header.stamp, f.pair.header.stamp);
  EXPECT_EQ(t.child_frame_id, "seg_9");
  EXPECT_DOUBLE_EQ(t.transform.translation.x, 0.5);
  EXPECT_DOUBLE_EQ(t.transform.translation.y, -0.25);
  EXPECT_DOUBLE_EQ(t.transform.translation.z, 2.0);
  EXPECT_NEAR(t.transform.rotation.z, std::sin(0.005), 1e-9);
  EXPECT_NEAR(t.transform.rotation.w, std::cos(0.005), 1e-9);
}

TEST(Conversions, MotionMarkersClearThenOneArrowAndTextPerSegment) {
  const Fixture f = makeFixture();
  const auto markers = mc_flow_ros::makeMotionMarkers(f.result, f.pair, 1.0);
  ASSERT_EQ(markers.markers.size(), 1u + 2u * 2u);
  EXPECT_EQ(markers.markers[0].action, visualization_msgs::Marker::DELETEALL);
  const auto& arrow = markers.markers[3];
  EXPECT_EQ(arrow.type, visualization_msgs::Marker::ARROW);
  EXPECT_EQ(arrow.id, 9);
  ASSERT_EQ(arrow.points.size(), 2u);
  // Centroid velocity over 0.1 s, drawn 1 s ahead.
  const Eigen::Vector3d v = mc_flow_ros::centroidVelocity(f.result.segments[1], 0.1);
  EXPECT_NEAR(arrow.points[1].x - arrow.points[0].x, v.x(), 1e-9);
  EXPECT_GT(v.x(), 0.15);
}

// With the static world known (segment 7 the world, 9 moving at 0.3 m/s in it): one arrow, for the moving segment,
// along its world-relative velocity; the world gets none, and it is drawn in the world's one colour in the pictures.
TEST(Conversions, WithTheWorldKnownOnlyMovingSegmentsGetArrowsAndTheWorldItsOwnColour) {
  Fixture f = makeFixture();
  f.result.world.found = true;
  f.result.world.ids = {7};
  std::vector<mc_flow::WorldVelocity> world(2);
  world[1].linear = Eigen::Vector3d(0, 0.3, 0);
  world[1].moving = true;
  f.pair.world = &world;
  const auto markers = mc_flow_ros::makeMotionMarkers(f.result, f.pair, 1.0);
  ASSERT_EQ(markers.markers.size(), 1u + 2u);
  const auto& arrow = markers.markers[1];
  EXPECT_EQ(arrow.id, 9);
  ASSERT_EQ(arrow.points.size(), 2u);
  EXPECT_NEAR(arrow.points[1].y - arrow.points[0].y, 0.3, 1e-9);
  EXPECT_NEAR(arrow.points[1].x - arrow.points[0].x, 0.0, 1e-9);
  world[1].moving = false;  // nothing moves: no arrow at all
  EXPECT_EQ(mc_flow_ros::makeMotionMarkers(f.result, f.pair, 1.0).markers.size(), 1u);

  const mc_flow::SegmentArray msg = mc_flow_ros::makeSegmentArray(f.result, f.pair);
  EXPECT_NEAR(msg.segments[0].color.r, mc_flow::kWorldColour.r / 255.f, 1e-6);
  EXPECT_NEAR(msg.segments[1].color.r, mc_flow::colourForId(9).r / 255.f, 1e-6);
  const cv::Mat picture = mc_flow_ros::segmentationPicture(f.result, f.pair, 1.0);
  // Pixel (1, 1): 0.75 of segment 7 (the world) and 0.25 of the outlier label's grey.
  const cv::Vec3b p = picture.at<cv::Vec3b>(1, 1);
  EXPECT_NEAR(p[0], 0.75 * mc_flow::kWorldColour.r + 0.25 * mc_flow::colourForId(0).r, 1.0);
  EXPECT_NEAR(p[2], 0.75 * mc_flow::kWorldColour.b + 0.25 * mc_flow::colourForId(0).b, 1.0);
}

// ~camera_path: the poses in the latest one's frame: the latest is the identity, an earlier one where the camera was.
TEST(Conversions, CameraPathIsThePosesInTheLatestCameraFrame) {
  std::deque<Eigen::Matrix4d> poses;
  Eigen::Matrix4d a = Eigen::Matrix4d::Identity(), b = Eigen::Matrix4d::Identity();
  b.topLeftCorner<3, 3>() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  b.topRightCorner<3, 1>() = Eigen::Vector3d(1, 0, 0);
  poses = {a, b};
  std_msgs::Header header;
  header.frame_id = "camera_rgb_optical_frame";
  const nav_msgs::Path path = mc_flow_ros::makeCameraPath(poses, header);
  ASSERT_EQ(path.poses.size(), 2u);
  EXPECT_EQ(path.header.frame_id, "camera_rgb_optical_frame");
  EXPECT_NEAR(path.poses[1].pose.position.x, 0.0, 1e-12);
  EXPECT_NEAR(path.poses[1].pose.orientation.w, 1.0, 1e-12);
  // The first pose in b's frame: b^-1 a, at b^-1 (0, 0, 0) = -R^T (1, 0, 0) = (0, 0, -1) for a quarter turn about y.
  EXPECT_NEAR(path.poses[0].pose.position.x, 0.0, 1e-12);
  EXPECT_NEAR(path.poses[0].pose.position.z, -1.0, 1e-12);
  EXPECT_TRUE(mc_flow_ros::makeCameraPath({}, header).poses.empty());
}

// ~odom: the base's pose M C M^-1 (it starts at the identity of the odom frame), the twist in the child frame, and the
// pose covariance as nav_msgs/Odometry means it (position and rotation errors in the odom frame): a heading
// uncertainty far from the origin must not turn into a position uncertainty (no lever arm about the odom origin).
TEST(Conversions, OdometryIsTheBasesWithItsCovarianceInTheOdomFrame) {
  mc_flow::Odometry odometry;
  odometry.pose.topRightCorner<3, 1>() = Eigen::Vector3d(0, 0, 10);  // 10 m ahead of the first pose (optical z)
  odometry.pose_covariance.bottomRightCorner<3, 3>() = 1e-4 * Eigen::Matrix3d::Identity();  // rotation only
  odometry.velocity << 0, 0, 1, 0, 0, 0;                                                    // 1 m/s forward (optical z)
  // The camera is mounted with the usual optical rotation: base x = camera z, base y = -camera x, base z = -camera y.
  Eigen::Isometry3d base_from_camera = Eigen::Isometry3d::Identity();
  base_from_camera.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const nav_msgs::Odometry msg =
      mc_flow_ros::makeOdometry(odometry, ros::Time(5.0), "odom", "base_link", base_from_camera);
  EXPECT_EQ(msg.header.frame_id, "odom");
  EXPECT_EQ(msg.child_frame_id, "base_link");
  EXPECT_NEAR(msg.pose.pose.position.x, 10.0, 1e-12);  // forward is the base's x
  EXPECT_NEAR(msg.pose.pose.position.y, 0.0, 1e-12);
  EXPECT_NEAR(msg.pose.pose.orientation.w, 1.0, 1e-12);
  EXPECT_NEAR(msg.twist.twist.linear.x, 1.0, 1e-12);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(msg.pose.covariance[std::size_t(6 * r + c)], 0.0, 1e-15) << r << "," << c;
  for (int k = 3; k < 6; ++k) EXPECT_NEAR(msg.pose.covariance[std::size_t(7 * k)], 1e-4, 1e-12);
}
