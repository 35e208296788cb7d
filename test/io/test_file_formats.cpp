// Round trips and parsers of the file I/O library: .flo, .pfm, .npy, camera_info YAML, intrinsics text,
// config files, depth/colour loading.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include <opencv2/imgcodecs.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/io/camera_info.h"
#include "mc_flow/io/config_file.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/visualization.h"

namespace fs = std::filesystem;
using namespace mc_flow;

namespace {

std::string tempPath(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("mcflow_io_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  return (dir / name).string();
}

ImageF randomImage(int w, int h, int c, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> dist(-50.f, 50.f);
  ImageF image(w, h, c);
  for (float& v : image.data) v = dist(rng);
  return image;
}

// Bitwise equality, so NaN == NaN and -0 != +0 are checked exactly.
void expectBitwiseEqual(const ImageF& a, const ImageF& b) {
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  ASSERT_EQ(a.channels, b.channels);
  ASSERT_EQ(0, std::memcmp(a.ptr(), b.ptr(), a.data.size() * sizeof(float)));
}

std::vector<char> fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<char>(std::istreambuf_iterator<char>(in), {});
}

}  // namespace

TEST(FlowIo, FloRoundTripKeepsValuesAndNaN) {
  ImageF flow = randomImage(37, 23, 2, 1);  // odd sizes catch stride mistakes
  flow(3, 4, 0) = flow(3, 4, 1) = std::nanf("");
  const std::string path = tempPath("a.flo");
  io::writeFlo(path, flow);
  expectBitwiseEqual(flow, io::readFlo(path));
  const std::vector<char> bytes = fileBytes(path);
  ASSERT_EQ(bytes.size(), 12u + 37u * 23u * 2u * 4u);
  EXPECT_EQ(std::string(bytes.data(), 4), "PIEH");
  std::int32_t size[2];
  std::memcpy(size, bytes.data() + 4, 8);
  EXPECT_EQ(size[0], 37);
  EXPECT_EQ(size[1], 23);
  float first_u;
  std::memcpy(&first_u, bytes.data() + 12, 4);
  EXPECT_EQ(first_u, flow(0, 0, 0));  // row-major from the top-left pixel
}

TEST(FlowIo, FloRejectsWrongChannelsAndBadMagic) {
  EXPECT_THROW(io::writeFlo(tempPath("b.flo"), ImageF(4, 4, 3)), InputError);
  const std::string path = tempPath("bad.flo");
  std::ofstream(path) << "this is not a flo file";
  EXPECT_THROW(io::readFlo(path), InputError);
  EXPECT_THROW(io::readFlo(tempPath("does_not_exist.flo")), InputError);
}

TEST(FlowIo, PfmRoundTripOneAndThreeChannels) {
  for (int channels : {1, 3}) {
    ImageF image = randomImage(19, 11, channels, 2 + channels);
    image(18, 10, 0) = std::nanf("");
    const std::string path = tempPath("c" + std::to_string(channels) + ".pfm");
    io::writePfm(path, image);
    expectBitwiseEqual(image, io::readPfm(path));
  }
}

TEST(FlowIo, PfmStoresRowsBottomToTopLittleEndian) {
  ImageF image(2, 2, 1);
  image.data = {1.f, 2.f, 3.f, 4.f};  // top row 1 2, bottom row 3 4
  const std::string path = tempPath("order.pfm");
  io::writePfm(path, image);
  const std::vector<char> bytes = fileBytes(path);
  const std::string header = "Pf\n2 2\n-1.0\n";
  ASSERT_EQ(std::string(bytes.data(), header.size()), header);
  float first;
  std::memcpy(&first, bytes.data() + header.size(), 4);
  EXPECT_EQ(first, 3.f);  // the bottom row comes first
}

TEST(FlowIo, PfmReadsBigEndianFiles) {
  const std::string path = tempPath("big.pfm");
  {
    std::ofstream out(path, std::ios::binary);
    out << "Pf\n2 1\n1.0\n";
    const std::uint8_t values[8] = {0x3f, 0x80, 0x00, 0x00, 0xc0, 0x00, 0x00, 0x00};  // 1.0f, -2.0f big endian
    out.write(reinterpret_cast<const char*>(values), 8);
  }
  const ImageF image = io::readPfm(path);
  ASSERT_EQ(image.width, 2);
  EXPECT_EQ(image(0, 0), 1.f);
  EXPECT_EQ(image(1, 0), -2.f);
}

TEST(FlowIo, NpyHeaderIsAlignedAndRoundTrips) {
  const std::vector<std::size_t> shape = {3, 5, 4};
  std::vector<float> data(60);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = float(i) * 0.5f;
  data[7] = std::nanf("");
  const std::string path = tempPath("a.npy");
  io::writeNpy(path, shape, data);
  const std::vector<char> bytes = fileBytes(path);
  ASSERT_GT(bytes.size(), 10u);
  EXPECT_EQ(std::string(bytes.data(), 6), "\x93NUMPY");
  EXPECT_EQ(bytes[6], 1);
  EXPECT_EQ(bytes[7], 0);
  const std::size_t header_len = std::uint8_t(bytes[8]) | (std::size_t(std::uint8_t(bytes[9])) << 8);
  EXPECT_EQ((10 + header_len) % 64, 0u);
  const std::string header(bytes.data() + 10, header_len);
  EXPECT_NE(header.find("'descr': '<f4'"), std::string::npos);
  EXPECT_NE(header.find("'fortran_order': False"), std::string::npos);
  EXPECT_NE(header.find("'shape': (3, 5, 4)"), std::string::npos);
  EXPECT_EQ(header.back(), '\n');
  EXPECT_EQ(bytes.size(), 10 + header_len + 60 * 4);

  const io::NpyArray back = io::readNpy(path);
  EXPECT_EQ(back.shape, shape);
  ASSERT_EQ(back.data.size(), data.size());
  EXPECT_EQ(0, std::memcmp(back.data.data(), data.data(), data.size() * 4));
}

TEST(FlowIo, SoftLabelsNpyIsHeightWidthLabels) {
  SoftLabels u(4, 3, 3);
  for (int i = 0; i < 3; ++i)
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 4; ++x) u.at(i, x, y) = float(100 * i + 10 * y + x);
  const std::string path = tempPath("u.npy");
  io::writeSoftLabelsNpy(path, u);
  const io::NpyArray raw = io::readNpy(path);
  ASSERT_EQ(raw.shape, (std::vector<std::size_t>{3, 4, 3}));
  // element [y][x][i] of a C-order (H, W, n) array
  EXPECT_EQ(raw.data[(2 * 4 + 1) * 3 + 2], u.at(2, 1, 2));
  const SoftLabels back = io::readSoftLabelsNpy(path);
  EXPECT_EQ(back.width, 4);
  EXPECT_EQ(back.height, 3);
  EXPECT_EQ(back.count, 3);
  EXPECT_EQ(back.data, u.data);
}

TEST(CameraInfo, ParsesMessageFormK) {
  const std::string yaml =
      "header:\n  seq: 0\n  frame_id: camera_rgb_optical_frame\nheight: 480\nwidth: 640\n"
      "distortion_model: \"plumb_bob\"\nD: [0.1, 0.0, 0.0, 0.0, 0.0]\n"
      "K: [525.0, 0.0, 319.5, 0.0, 526.0, 239.5, 0.0, 0.0, 1.0]\n"
      "R: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n"
      "P: [500.0, 0.0, 300.0, 0.0, 0.0, 501.0, 200.0, 0.0, 0.0, 0.0, 1.0, 0.0]\n"
      "roi:\n  x_offset: 0\n  height: 0\n  width: 0\n";
  const io::CameraInfo info = io::parseCameraInfoYaml(yaml, "test");
  EXPECT_EQ(info.intrinsics.fx, 525.0);
  EXPECT_EQ(info.intrinsics.fy, 526.0);
  EXPECT_EQ(info.intrinsics.cx, 319.5);
  EXPECT_EQ(info.intrinsics.cy, 239.5);
  EXPECT_EQ(info.width, 640);
  EXPECT_EQ(info.height, 480);
}

TEST(CameraInfo, ParsesCalibrationFileFormAndFallsBackToP) {
  const std::string calibration =
      "image_width: 320\nimage_height: 240\ncamera_name: rgb\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
      "  data: [260.0, 0, 160.5,\n         0, 261.0, 120.5,\n         0, 0, 1]\n"
      "projection_matrix:\n  rows: 3\n  cols: 4\n  data: [1, 0, 2, 0, 0, 3, 4, 0, 0, 0, 1, 0]\n";
  io::CameraInfo info = io::parseCameraInfoYaml(calibration, "test");
  EXPECT_EQ(info.intrinsics.fx, 260.0);
  EXPECT_EQ(info.intrinsics.fy, 261.0);
  EXPECT_EQ(info.intrinsics.cx, 160.5);
  EXPECT_EQ(info.intrinsics.cy, 120.5);
  EXPECT_EQ(info.width, 320);

  const std::string only_p = "K: [0, 0, 0, 0, 0, 0, 0, 0, 0]\nP:\n- 500\n- 0\n- 310\n- 0\n- 0\n- 502\n- 230\n- 0\n- 0\n- 0\n- 1\n- 0\n";
  info = io::parseCameraInfoYaml(only_p, "test");
  EXPECT_EQ(info.intrinsics.fx, 500.0);
  EXPECT_EQ(info.intrinsics.fy, 502.0);
  EXPECT_EQ(info.intrinsics.cx, 310.0);
  EXPECT_EQ(info.intrinsics.cy, 230.0);
}

TEST(CameraInfo, RejectsMissingMatrixAndNamesTheSource) {
  try {
    io::parseCameraInfoYaml("width: 640\nheight: 480\n", "my_camera.yaml");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("my_camera.yaml"), std::string::npos);
  }
}

TEST(CameraInfo, SaveLoadRoundTrip) {
  io::CameraInfo info;
  info.intrinsics = {201.25, 202.5, 80.125, 59.75};
  info.width = 160;
  info.height = 120;
  const std::string path = tempPath("camera_info.yaml");
  io::saveCameraInfo(path, info);
  const io::CameraInfo back = io::loadCameraInfo(path);
  EXPECT_EQ(back.intrinsics.fx, 201.25);
  EXPECT_EQ(back.intrinsics.fy, 202.5);
  EXPECT_EQ(back.intrinsics.cx, 80.125);
  EXPECT_EQ(back.intrinsics.cy, 59.75);
  EXPECT_EQ(back.width, 160);
  EXPECT_EQ(back.height, 120);
}

TEST(Intrinsics, ParsesAndFormatsExactly) {
  const Intrinsics K = io::parseIntrinsics(" 525.5, 524.25 ,319.5,239.5");
  EXPECT_EQ(K.fx, 525.5);
  EXPECT_EQ(K.fy, 524.25);
  EXPECT_EQ(K.cx, 319.5);
  EXPECT_EQ(K.cy, 239.5);
  const Intrinsics odd{1.0 / 3.0, 2.0 / 7.0, 0.1, 0.2};
  const Intrinsics back = io::parseIntrinsics(io::formatIntrinsics(odd));
  EXPECT_EQ(back.fx, odd.fx);
  EXPECT_EQ(back.fy, odd.fy);
  EXPECT_EQ(back.cx, odd.cx);
  EXPECT_EQ(back.cy, odd.cy);
}

TEST(Intrinsics, RejectsMalformedAndNonPositiveWithTheText) {
  for (const std::string bad : {"abc", "1,2,3", "1,2,3,4,5", "525,x,1,2", ""}) {
    try {
      io::parseIntrinsics(bad);
      FAIL() << "accepted '" << bad << "'";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("'" + bad + "'"), std::string::npos) << e.what();
    }
  }
  try {
    io::parseIntrinsics("0,525,319.5,239.5");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("fx"), std::string::npos) << e.what();
  }
  EXPECT_THROW(io::parseIntrinsics("525,-1,319.5,239.5"), InputError);
}

TEST(ImageIo, DepthScalesOf16BitPng) {
  cv::Mat raw(3, 4, CV_16UC1, cv::Scalar(0));
  raw.at<std::uint16_t>(0, 0) = 1000;
  raw.at<std::uint16_t>(1, 2) = 2500;
  raw.at<std::uint16_t>(2, 3) = 65535;
  const std::string path = tempPath("depth16.png");
  ASSERT_TRUE(cv::imwrite(path, raw));
  ImageF mm = io::loadDepth(path, 1000.0);
  ASSERT_EQ(mm.width, 4);
  ASSERT_EQ(mm.height, 3);
  EXPECT_FLOAT_EQ(mm(0, 0), 1.0f);
  EXPECT_FLOAT_EQ(mm(2, 1), 2.5f);
  EXPECT_FLOAT_EQ(mm(3, 2), 65.535f);
  EXPECT_EQ(mm(1, 0), 0.f);
  ImageF tum = io::loadDepth(path, 5000.0);
  EXPECT_FLOAT_EQ(tum(0, 0), 0.2f);
  EXPECT_FLOAT_EQ(tum(2, 1), 0.5f);
}

TEST(ImageIo, DepthSaveLoadRoundTripInMillimetres) {
  ImageF depth(5, 2, 1, 0.f);
  depth(0, 0) = 1.2344f;  // rounds to 1234 mm
  depth(4, 1) = std::nanf("");
  depth(1, 1) = 3.0f;
  const std::string path = tempPath("saved_depth.png");
  io::saveDepthPng16(path, depth, 1000.0);
  const cv::Mat raw = cv::imread(path, cv::IMREAD_ANYDEPTH);
  ASSERT_EQ(raw.type(), CV_16UC1);
  EXPECT_EQ(raw.at<std::uint16_t>(0, 0), 1234);
  EXPECT_EQ(raw.at<std::uint16_t>(1, 4), 0);
  const ImageF back = io::loadDepth(path, 1000.0);
  EXPECT_FLOAT_EQ(back(1, 1), 3.0f);
}

TEST(ImageIo, FloatDepthFromPfmAndTiff) {
  ImageF depth(3, 2, 1, 0.f);
  depth(2, 1) = 1.2345678f;
  depth(0, 0) = std::nanf("");
  const std::string pfm = tempPath("depth.pfm");
  io::writePfm(pfm, depth);
  EXPECT_EQ(io::loadDepth(pfm, 1000.0)(2, 1), 1.2345678f);  // float depth ignores the 16-bit scale

  cv::Mat m(2, 3, CV_32FC1, cv::Scalar(0));
  m.at<float>(1, 2) = 2.75f;
  const std::string tiff = tempPath("depth.tiff");
  ASSERT_TRUE(cv::imwrite(tiff, m));
  EXPECT_EQ(io::loadDepth(tiff, 1000.0)(2, 1), 2.75f);
}

TEST(ImageIo, RejectsEightBitAndAllInvalidDepthNamingTheFile) {
  const std::string eight = tempPath("depth8.png");
  ASSERT_TRUE(cv::imwrite(eight, cv::Mat(4, 4, CV_8UC1, cv::Scalar(100))));
  try {
    io::loadDepth(eight, 1000.0);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(eight), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("16-bit"), std::string::npos);
  }
  const std::string zero = tempPath("depth_zero.png");
  ASSERT_TRUE(cv::imwrite(zero, cv::Mat(4, 4, CV_16UC1, cv::Scalar(0))));
  try {
    io::loadDepth(zero, 1000.0);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(zero), std::string::npos);
  }
  try {
    io::loadDepth(tempPath("missing_depth.png"), 1000.0);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing_depth.png"), std::string::npos);
  }
}

TEST(ImageIo, IntensityUsesRec601WeightsOnBgr) {
  cv::Mat bgr(1, 4, CV_8UC3);
  bgr.at<cv::Vec3b>(0, 0) = {0, 0, 255};    // pure red
  bgr.at<cv::Vec3b>(0, 1) = {0, 255, 0};    // pure green
  bgr.at<cv::Vec3b>(0, 2) = {255, 0, 0};    // pure blue
  bgr.at<cv::Vec3b>(0, 3) = {51, 102, 204}; // mixed
  const ImageF i = io::intensityFromMat(bgr, "test");
  EXPECT_NEAR(i(0, 0), 0.299f, 1e-6);
  EXPECT_NEAR(i(1, 0), 0.587f, 1e-6);
  EXPECT_NEAR(i(2, 0), 0.114f, 1e-6);
  EXPECT_NEAR(i(3, 0), (0.299 * 204 + 0.587 * 102 + 0.114 * 51) / 255.0, 1e-6);

  // Through a file: colour PNG and 16-bit grey PNG.
  const std::string colour = tempPath("colour.png");
  ASSERT_TRUE(cv::imwrite(colour, bgr));
  ImageU8 rgb;
  const ImageF loaded = io::loadIntensity(colour, &rgb);
  EXPECT_NEAR(loaded(0, 0), 0.299f, 1e-6);
  EXPECT_EQ(rgb(0, 0, 0), 255);  // R first in the returned RGB image
  EXPECT_EQ(rgb(0, 0, 2), 0);
  const std::string grey16 = tempPath("grey16.png");
  ASSERT_TRUE(cv::imwrite(grey16, cv::Mat(1, 2, CV_16UC1, cv::Scalar(65535 / 5))));
  EXPECT_NEAR(io::loadIntensity(grey16)(1, 0), 0.2f, 1e-6);
}

TEST(ImageIo, LabelsAreEightOrSixteenBit) {
  ImageI32 labels(3, 1, 1, 0);
  labels(1, 0) = 7;
  labels(2, 0) = 255;
  const std::string small = tempPath("labels8.png");
  io::saveLabels(small, labels);
  EXPECT_EQ(cv::imread(small, cv::IMREAD_UNCHANGED).type(), CV_8UC1);
  EXPECT_EQ(io::loadLabels(small).data, labels.data);
  labels(0, 0) = 300;
  const std::string large = tempPath("labels16.png");
  io::saveLabels(large, labels);
  EXPECT_EQ(cv::imread(large, cv::IMREAD_UNCHANGED).type(), CV_16UC1);
  EXPECT_EQ(io::loadLabels(large).data, labels.data);
}

TEST(ConfigFile, JsonAndYamlSetFields) {
  const std::string json = tempPath("config.json");
  std::ofstream(json) << "{\n  \"alpha\": 3.5,\n  \"initial_labels\": 12,\n  \"regularizer\": \"tv\",\n"
                         "  \"detect_occlusions\": false\n}\n";
  Config a;
  io::applyConfigFile(json, a);
  EXPECT_EQ(a.alpha, 3.5);
  EXPECT_EQ(a.initial_labels, 12);
  EXPECT_EQ(a.regularizer, Regularizer::TotalVariation);
  EXPECT_FALSE(a.detect_occlusions);

  const std::string yaml = tempPath("config.yaml");
  std::ofstream(yaml) << "# solver settings\nalpha: 1.25   # weight\ninitial_labels: 9\nregularizer: quad\n";
  Config b;
  io::applyConfigFile(yaml, b);
  EXPECT_EQ(b.alpha, 1.25);
  EXPECT_EQ(b.initial_labels, 9);
  EXPECT_EQ(b.regularizer, Regularizer::Quadratic);
}

TEST(ConfigFile, ErrorsNameFileAndKey) {
  const std::string path = tempPath("bad_config.yaml");
  std::ofstream(path) << "alpha: 2\nno_such_field: 1\n";
  Config c;
  try {
    io::applyConfigFile(path, c);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no_such_field"), std::string::npos) << e.what();
  }
  const std::string nested = tempPath("nested.json");
  std::ofstream(nested) << "{\"alpha\": {\"x\": 1}}";
  EXPECT_THROW(io::applyConfigFile(nested, c), ConfigError);
  EXPECT_THROW(io::applyConfigAssignment("alpha", c), ConfigError);
  io::applyConfigAssignment("alpha=0.75", c);
  EXPECT_EQ(c.alpha, 0.75);
}

TEST(Json, WriterEscapesAndWritesNullForNonFinite) {
  io::JsonWriter w;
  w.beginObject().key("text").value("a\"b\\c\n").key("nan").value(std::nan("")).key("list").numbers({1.5, 2}).endObject();
  EXPECT_NE(w.str().find("\"a\\\"b\\\\c\\n\""), std::string::npos) << w.str();
  EXPECT_NE(w.str().find("\"nan\": null"), std::string::npos) << w.str();
  EXPECT_NE(w.str().find("[1.5, 2]"), std::string::npos) << w.str();
  EXPECT_EQ(io::configValueToJson("0.25"), "0.25");
  EXPECT_EQ(io::configValueToJson("true"), "true");
  EXPECT_EQ(io::configValueToJson("quad"), "\"quad\"");
}

TEST(Visualization, FlowColourWheelDirectionsAndInvalid) {
  ImageF flow(4, 1, 2, 0.f);
  flow(0, 0, 0) = 1.f;   // rightwards: red in the Middlebury coding
  flow(1, 0, 0) = -1.f;  // leftwards: cyan/blue
  flow(2, 0, 0) = std::nanf("");
  // pixel 3: zero flow -> white
  const cv::Mat image = io::flowColorImage(flow);
  const cv::Vec3b right = image.at<cv::Vec3b>(0, 0), left = image.at<cv::Vec3b>(0, 1);
  EXPECT_GT(right[2], 200);         // R
  EXPECT_LT(right[1], 60);          // G
  EXPECT_GT(left[0], 200);          // B
  EXPECT_LT(left[2], 60);           // R
  EXPECT_EQ(image.at<cv::Vec3b>(0, 2), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(image.at<cv::Vec3b>(0, 3), cv::Vec3b(255, 255, 255));
}

TEST(Visualization, SegmentationBlendsColoursOverImage) {
  SoftLabels u(2, 1, 3);  // two segments + outlier
  u.at(0, 0, 0) = 1.f;    // pixel 0: segment 0
  u.at(2, 1, 0) = 1.f;    // pixel 1: outlier
  ImageF grey(2, 1, 1, 0.5f);
  const cv::Mat image = io::segmentationImage(u, grey);
  const cv::Vec3b c0 = io::segmentColor(0);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(image.at<cv::Vec3b>(0, 0)[k], 0.6 * c0[k] + 0.4 * 127.5, 1.0);
    EXPECT_NEAR(image.at<cv::Vec3b>(0, 1)[k], 0.4 * 127.5, 1.0);  // outlier is black under the blend
  }
  EXPECT_NE(io::segmentColor(0), io::segmentColor(1));
  EXPECT_EQ(io::segmentColor(25), io::segmentColor(25));
}
