// Rosbags as sequences: the reader (mc_flow_ros::BagSequence) on small bags written here with the rosbag API,
// and `mcflow run-seq --bag` end to end on one of them. Every bag lives in a temporary folder removed at exit.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <rosbag/bag.h>
#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include "mc_flow/ros/bag_sequence.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "temp_dir.h"

#ifndef MCFLOW_CLI_PATH
#error "MCFLOW_CLI_PATH must name the mcflow binary"
#endif

namespace fs = std::filesystem;
using mc_flow_ros::BagReadOptions;
using mc_flow_ros::BagSequence;

namespace {

constexpr int kWidth = 96, kHeight = 72;  // processed as is (chooseDownsample: factor 1)
constexpr const char* kRgb = "/camera/rgb/image_rect_color";
constexpr const char* kDepth = "/camera/depth_registered/image_rect";
constexpr const char* kInfo = "/camera/rgb/camera_info";
const ros::Time kStart(500.0);
constexpr double kInterval = 0.1;  // [s]

fs::path workDir() {
  static const mc_flow::test::TempDir dir("mcflow_bag_");
  return dir.path();
}

/// What a test bag holds; the defaults make a clean 4-frame stream on the default topics.
struct BagSpec {
  int frames = 4;
  std::string rgb_topic = kRgb, depth_topic = kDepth, info_topic = kInfo;
  bool with_info = true;
  std::string rgb_encoding = "bgr8";       // a conversion the reader must do (the renderer gives RGB)
  std::string depth_encoding = "16UC1";    // millimetres
  double depth_offset = 0.004;             // [s] depth stamps after the colour ones (a real camera's skew)
  int extra_rgb_without_depth_after = -1;  // a colour message with no depth near it, after this frame
  int zero_depth_frame = -1;               // this frame's depth is all zero (a camera starting up)
};

ros::Time stampOf(int t) { return kStart + ros::Duration(kInterval * t); }

sensor_msgs::Image colourMessage(const mc_flow::ImageU8& colour, const ros::Time& stamp, const std::string& encoding) {
  sensor_msgs::Image m;
  m.header.stamp = stamp;
  m.header.frame_id = "bag_test_optical_frame";
  m.width = std::uint32_t(colour.width);
  m.height = std::uint32_t(colour.height);
  m.encoding = encoding;
  m.step = m.width * 3;
  m.data.assign(colour.data.begin(), colour.data.end());
  if (encoding == "bgr8")
    for (std::size_t i = 0; i + 2 < m.data.size(); i += 3) std::swap(m.data[i], m.data[i + 2]);
  return m;
}

sensor_msgs::Image depthMessage(const mc_flow::ImageF& depth, const ros::Time& stamp, const std::string& encoding,
                                bool all_zero) {
  sensor_msgs::Image m;
  m.header.stamp = stamp;
  m.header.frame_id = "bag_test_optical_frame";
  m.width = std::uint32_t(depth.width);
  m.height = std::uint32_t(depth.height);
  m.encoding = encoding;
  if (encoding == "16UC1") {
    m.step = m.width * 2;
    m.data.resize(std::size_t(m.step) * m.height);
    for (std::size_t i = 0; i < depth.data.size(); ++i) {
      const float z = depth.data[i];
      const std::uint16_t mm = !all_zero && mc_flow::isValidDepth(z) ? std::uint16_t(std::lround(z * 1000.f)) : 0;
      std::memcpy(&m.data[2 * i], &mm, 2);
    }
  } else {
    m.step = m.width * 4;
    m.data.resize(std::size_t(m.step) * m.height);
    for (std::size_t i = 0; i < depth.data.size(); ++i) {
      const float z = !all_zero && mc_flow::isValidDepth(depth.data[i]) ? depth.data[i] : 0.f;
      std::memcpy(&m.data[4 * i], &z, 4);
    }
  }
  return m;
}

sensor_msgs::CameraInfo infoMessage(const mc_flow::Intrinsics& K, const ros::Time& stamp) {
  sensor_msgs::CameraInfo m;
  m.header.stamp = stamp;
  m.header.frame_id = "bag_test_optical_frame";
  m.width = kWidth;
  m.height = kHeight;
  m.distortion_model = "plumb_bob";
  m.D.assign(5, 0.0);
  m.K = {K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1};
  m.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  m.P = {K.fx, 0, K.cx, 0, 0, K.fy, K.cy, 0, 0, 0, 1, 0};
  return m;
}

/// The synthetic sequence's frames, rendered once per test process.
const std::pair<mc_flow::RgbdFrame, mc_flow::ImageU8>& renderedFrame(int t, mc_flow::Intrinsics* K = nullptr) {
  static std::map<int, std::pair<mc_flow::RgbdFrame, mc_flow::ImageU8>> frames;
  static mc_flow::Intrinsics intrinsics;
  if (!frames.count(t)) {
    mc_flow::SyntheticSceneOptions options;
    options.width = kWidth;
    options.height = kHeight;
    auto& f = frames[t];
    mc_flow::renderSyntheticFrame(options, t, f.first, f.second, intrinsics);
  }
  if (K) *K = intrinsics;
  return frames[t];
}

fs::path writeBag(const std::string& name, const BagSpec& spec) {
  const fs::path path = workDir() / name;
  ros::Time::init();  // the bag's connection headers; no node needed
  rosbag::Bag bag(path.string(), rosbag::bagmode::Write);
  for (int t = 0; t < spec.frames; ++t) {
    mc_flow::Intrinsics K;
    const auto& [frame, colour] = renderedFrame(t, &K);
    const ros::Time stamp = stampOf(t);
    if (spec.with_info) bag.write(spec.info_topic, stamp, infoMessage(K, stamp));
    bag.write(spec.rgb_topic, stamp, colourMessage(colour, stamp, spec.rgb_encoding));
    const ros::Time depth_stamp = stamp + ros::Duration(spec.depth_offset);
    bag.write(spec.depth_topic, depth_stamp,
              depthMessage(frame.depth, depth_stamp, spec.depth_encoding, t == spec.zero_depth_frame));
    if (t == spec.extra_rgb_without_depth_after) {
      const ros::Time between = stamp + ros::Duration(kInterval / 2);  // 50 ms from any depth
      bag.write(spec.rgb_topic, between, colourMessage(colour, between, spec.rgb_encoding));
    }
  }
  bag.close();
  return path;
}

/// InputError's message, or "" when `make` does not throw one.
template <class F>
std::string inputError(F make) {
  try {
    make();
  } catch (const mc_flow::InputError& e) {
    return e.what();
  }
  return "";
}

struct CliRun {
  int code = -1;
  std::string out, err;
};

std::string quote(const std::string& s) { return "'" + s + "'"; }

std::string readFile(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

CliRun runCli(const std::string& arguments) {
  static int counter = 0;
  const std::string tag = std::to_string(counter++);
  const fs::path out = workDir() / ("stdout_" + tag), err = workDir() / ("stderr_" + tag);
  const std::string command =
      quote(MCFLOW_CLI_PATH) + " " + arguments + " >" + quote(out.string()) + " 2>" + quote(err.string());
  const int status = std::system(command.c_str());
  CliRun run;
  run.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.out = readFile(out);
  run.err = readFile(err);
  return run;
}

/// The id that labels most pixels of a labels.png (16-bit ids, 0 = none).
int mostCommonId(const fs::path& labels_png) {
  const cv::Mat labels = cv::imread(labels_png.string(), cv::IMREAD_UNCHANGED);
  std::map<int, int> count;
  for (int y = 0; y < labels.rows; ++y)
    for (int x = 0; x < labels.cols; ++x) {
      const int id = labels.depth() == CV_16U ? labels.at<std::uint16_t>(y, x) : labels.at<std::uint8_t>(y, x);
      if (id > 0) ++count[id];
    }
  int best = 0, n = 0;
  for (const auto& [id, c] : count)
    if (c > n) best = id, n = c;
  return best;
}

}  // namespace

// ---------------------------------------------------------------- the reader

TEST(BagSequence, PairsColourAndDepthByTheNearestStampAndConvertsLikeTheNodelet) {
  BagSpec spec;
  spec.extra_rgb_without_depth_after = 1;  // 5 colour messages, 4 depth: one colour frame stays unpaired
  const fs::path path = writeBag("pairing.bag", spec);
  const BagSequence bag(path.string(), BagReadOptions());
  ASSERT_EQ(bag.size(), 4u) << bag.summary();
  EXPECT_NE(bag.summary().find("4 frame(s) from 5 message(s) on /camera/rgb/image_rect_color and 4 on"),
            std::string::npos)
      << bag.summary();
  EXPECT_NE(bag.summary().find("intrinsics from the first camera_info on /camera/rgb/camera_info"), std::string::npos);

  mc_flow::Intrinsics K;
  for (int t = 0; t < 4; ++t) {
    const mc_flow_ros::BagFrame f = bag.frame(std::size_t(t));
    const auto& [truth, colour] = renderedFrame(t, &K);
    EXPECT_NEAR(f.frame.stamp, stampOf(t).toSec(), 1e-9) << "frame " << t << " has the colour message's stamp";
    EXPECT_EQ(f.frame.source, "bag_test_optical_frame");
    ASSERT_EQ(f.frame.frame.width(), kWidth);
    ASSERT_EQ(f.frame.frame.height(), kHeight);
    EXPECT_DOUBLE_EQ(f.frame.K.fx, K.fx);
    EXPECT_DOUBLE_EQ(f.frame.K.cy, K.cy);
    // bgr8 back to RGB, 16UC1 millimetres to metres.
    ASSERT_EQ(f.colour.data.size(), colour.data.size());
    EXPECT_EQ(f.colour.data, colour.data) << "frame " << t;
    double worst = 0;
    for (std::size_t i = 0; i < truth.depth.data.size(); ++i)
      if (mc_flow::isValidDepth(truth.depth.data[i]))
        worst = std::max(worst, double(std::fabs(f.frame.frame.depth.data[i] - truth.depth.data[i])));
    EXPECT_LE(worst, 0.0005 + 1e-6) << "frame " << t << ": depth off by more than the millimetre rounding";
    EXPECT_NE(f.rgb_name.find(std::string(kRgb) + "@"), std::string::npos) << f.rgb_name;
  }

  // The 4 ms skew is within the default 20 ms; with 1 ms nothing pairs, and the error says what was looked for.
  BagReadOptions strict;
  strict.max_stamp_difference = 0.001;
  const std::string error = inputError([&] { BagSequence(path.string(), strict); });
  EXPECT_NE(error.find("no message on '/camera/rgb/image_rect_color' has one on '/camera/depth_registered/image_rect' "
                       "within 0.001 s"),
            std::string::npos)
      << error;
  EXPECT_NE(error.find("--max-stamp-difference"), std::string::npos) << error;
}

TEST(BagSequence, GivenIntrinsicsReplaceTheCameraInfoAndOtherTopicNamesAreRead) {
  BagSpec spec;
  spec.rgb_topic = "/cam/color/image_raw";
  spec.depth_topic = "/cam/aligned_depth_to_color/image_raw";
  spec.with_info = false;
  spec.depth_encoding = "32FC1";
  spec.rgb_encoding = "rgb8";
  const fs::path path = writeBag("realsense_names.bag", spec);
  BagReadOptions options;
  options.topics.rgb = "cam/color/image_raw";  // relative names are taken as absolute
  options.topics.depth = "/cam/aligned_depth_to_color/image_raw";
  // No camera_info in this bag: named, with the ways out.
  const std::string error = inputError([&] { BagSequence(path.string(), options); });
  EXPECT_NE(error.find("no message on --info-topic '/camera/rgb/camera_info' (give --info-topic, --intrinsics or "
                       "--camera-info)"),
            std::string::npos)
      << error;
  options.intrinsics = mc_flow::Intrinsics{100, 101, 47.5, 35.5};
  const BagSequence bag(path.string(), options);
  ASSERT_EQ(bag.size(), 4u);
  const mc_flow_ros::BagFrame f = bag.frame(0);
  EXPECT_DOUBLE_EQ(f.frame.K.fx, 100);
  EXPECT_DOUBLE_EQ(f.frame.K.fy, 101);
  EXPECT_DOUBLE_EQ(f.frame.K.cx, 47.5);
  EXPECT_NE(bag.summary().find("intrinsics given"), std::string::npos) << bag.summary();
}

TEST(BagSequence, WrongTopicsAndFilesAreNamed) {
  const fs::path path = writeBag("names.bag", BagSpec());
  BagReadOptions options;
  options.topics.rgb = "/camera/color/image_raw";
  std::string error = inputError([&] { BagSequence(path.string(), options); });
  EXPECT_NE(error.find("has no message on --rgb-topic '/camera/color/image_raw'"), std::string::npos) << error;
  // ... and lists what the bag holds, so the right name can be picked.
  EXPECT_NE(error.find("topics in the bag: /camera/depth_registered/image_rect (sensor_msgs/Image, 4), "
                       "/camera/rgb/camera_info (sensor_msgs/CameraInfo, 4), /camera/rgb/image_rect_color "
                       "(sensor_msgs/Image, 4)"),
            std::string::npos)
      << error;

  options = BagReadOptions();
  options.topics.depth = kInfo;  // a topic of another type
  error = inputError([&] { BagSequence(path.string(), options); });
  EXPECT_NE(error.find("--depth-topic '/camera/rgb/camera_info' holds sensor_msgs/CameraInfo messages, not "
                       "sensor_msgs/Image"),
            std::string::npos)
      << error;

  // The right type of another definition (a bag recorded with other message versions).
  const fs::path old_definition = workDir() / "old_definition.bag";
  {
    rosbag::Bag bag(old_definition.string(), rosbag::bagmode::Write);
    mc_flow::Intrinsics K;
    const auto& [frame, colour] = renderedFrame(0, &K);
    auto header = boost::make_shared<ros::M_string>();
    (*header)["topic"] = kRgb;
    (*header)["type"] = "sensor_msgs/Image";
    (*header)["md5sum"] = "0123456789abcdef0123456789abcdef";
    (*header)["message_definition"] = ros::message_traits::definition<sensor_msgs::Image>();
    bag.write(kRgb, stampOf(0), colourMessage(colour, stampOf(0), "rgb8"), header);
    bag.write(kDepth, stampOf(0), depthMessage(frame.depth, stampOf(0), "32FC1", false));
  }
  error = inputError([&] { BagSequence(old_definition.string(), BagReadOptions()); });
  EXPECT_NE(error.find("--rgb-topic '/camera/rgb/image_rect_color' holds sensor_msgs/Image of another definition "
                       "(md5sum 0123456789abcdef0123456789abcdef"),
            std::string::npos)
      << error;

  error = inputError([&] { BagSequence((workDir() / "missing.bag").string(), BagReadOptions()); });
  EXPECT_NE(error.find("missing.bag': does not exist"), std::string::npos) << error;
  const fs::path not_a_bag = workDir() / "not_a.bag";
  std::ofstream(not_a_bag) << "this is not a bag\n";
  error = inputError([&] { BagSequence(not_a_bag.string(), BagReadOptions()); });
  EXPECT_NE(error.find("not_a.bag' cannot be read"), std::string::npos) << error;
}

TEST(BagSequence, AnUnsupportedEncodingIsNamedWithTheFrame) {
  BagSpec spec;
  spec.frames = 2;
  spec.rgb_encoding = "yuv422";
  const fs::path path = writeBag("yuv.bag", spec);
  const BagSequence bag(path.string(), BagReadOptions());
  try {
    bag.frame(0);
    FAIL() << "a yuv422 frame was converted";
  } catch (const mc_flow_ros::FrameInputError& e) {
    EXPECT_EQ(e.problem, mc_flow_ros::InputProblem::Encoding);
    EXPECT_NE(std::string(e.what()).find("frame 0 (stamp 500.000000000)"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("yuv422"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------- mcflow run-seq --bag

// The bag's first depth image is empty (a camera starting up): that frame is skipped, the other three make two
// pairs, the second warm, and the background keeps its id. The layout is run-seq --tum's.
TEST(RunSeqBag, WritesTheSequenceFilesAndIdsPersist) {
  BagSpec spec;
  spec.frames = 5;
  spec.zero_depth_frame = 0;
  const fs::path bag = writeBag("stream.bag", spec), out = workDir() / "stream_out";
  const CliRun run = runCli("run-seq --bag " + quote(bag.string()) + " --out " + quote(out.string()));
  ASSERT_EQ(run.code, 0) << run.err;
  EXPECT_NE(run.out.find("3 pair(s) solved (2 warm"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("1 frame(s) skipped"), std::string::npos) << run.out;
  EXPECT_NE(run.err.find("skipped: frame 0 (stamp 500.000000000)"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("has no valid pixel"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("3/4 pairs"), std::string::npos) << "the progress bar: " << run.err;
  for (const char* f : {"pair_0000/labels.png", "pair_0000/report.json", "pair_0002/segments.json",
                        "pair_0002/overview.png", "trajectories.csv", "sequence.json", "ids_over_time.png"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  EXPECT_FALSE(fs::exists(out / "pair_0003"));
  const std::string log = readFile(out / "sequence.json");
  EXPECT_NE(log.find("\"pair\": 1, \"stamp\": 500.3, \"start\": \"warm\""), std::string::npos) << log;
  EXPECT_NE(log.find("\"pair\": 2, \"stamp\": 500.4, \"start\": \"warm\""), std::string::npos) << log;
  const std::string report = readFile(out / "pair_0001/report.json");
  EXPECT_NE(report.find(bag.string() + ":/camera/rgb/image_rect_color@500.300000000"), std::string::npos) << report;
  EXPECT_EQ(mostCommonId(out / "pair_0000/labels.png"), mostCommonId(out / "pair_0002/labels.png"));
  EXPECT_GT(mostCommonId(out / "pair_0000/labels.png"), 0);
}

TEST(RunSeqBag, BadInputEndsWithAMessageNamingIt) {
  const fs::path bag = writeBag("cli_names.bag", BagSpec());
  CliRun run = runCli("run-seq --bag " + quote(bag.string()) + " --rgb-topic /camera/color/image_raw --out " +
                      quote((workDir() / "x").string()));
  EXPECT_EQ(run.code, 1);
  EXPECT_NE(run.err.find("input error: bag '" + bag.string() +
                         "' has no message on --rgb-topic "
                         "'/camera/color/image_raw'; topics in the bag: "),
            std::string::npos)
      << run.err;
  EXPECT_FALSE(fs::exists(workDir() / "x")) << "nothing is written before the input is known to be usable";

  run = runCli("run-seq --bag " + quote((workDir() / "none.bag").string()) + " --out " +
               quote((workDir() / "y").string()));
  EXPECT_EQ(run.code, 1);
  EXPECT_NE(run.err.find("none.bag': does not exist"), std::string::npos) << run.err;

  BagSpec yuv;
  yuv.rgb_encoding = "yuv422";
  yuv.frames = 2;
  const fs::path yuv_bag = writeBag("cli_yuv.bag", yuv);
  run = runCli("run-seq --bag " + quote(yuv_bag.string()) + " --out " + quote((workDir() / "z").string()));
  EXPECT_EQ(run.code, 1);
  EXPECT_NE(run.err.find("yuv422"), std::string::npos) << run.err;

  run =
      runCli("run-seq --bag " + quote(bag.string()) + " --depth-scale 5000 --out " + quote((workDir() / "w").string()));
  EXPECT_EQ(run.code, 2);
  EXPECT_NE(run.err.find("--depth-scale is for --tum/--frames"), std::string::npos) << run.err;
  run = runCli("run-seq --tum " + quote(workDir().string()) + " --rgb-topic /a --out " +
               quote((workDir() / "v").string()));
  EXPECT_EQ(run.code, 2);
  EXPECT_NE(run.err.find("--rgb-topic is for --bag"), std::string::npos) << run.err;
}
