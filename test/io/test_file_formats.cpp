// Round trips and parsers of the file I/O library: .flo, .pfm, .npy, camera_info YAML, intrinsics text,
// config files (JSON and YAML), the JSON outputs, depth/colour loading.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/core/palette.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/io/camera_info.h"
#include "mc_flow/io/config_file.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/visualization.h"
#include "temp_dir.h"

namespace fs = std::filesystem;
using namespace mc_flow;

namespace {

std::string tempPath(const std::string& name) {
  static const test::TempDir dir("mcflow_io_");
  return (dir.path() / name).string();
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

// A header may claim any size: the loaders compare it with the bytes in the file before allocating.
TEST(FlowIo, HugeHeadersWithTinyFilesAreRefusedBeforeAllocating) {
  const std::string flo = tempPath("huge.flo");
  {
    std::ofstream out(flo, std::ios::binary);
    const float magic = 202021.25f;
    const std::int32_t size[2] = {2000000000, 2000000000};
    out.write(reinterpret_cast<const char*>(&magic), 4);
    out.write(reinterpret_cast<const char*>(size), 8);
    out << "12345678";
  }
  try {
    io::readFlo(flo);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("2000000000x2000000000"), std::string::npos) << e.what();
  }
  const std::string pfm = tempPath("huge.pfm");
  std::ofstream(pfm, std::ios::binary) << "Pf\n100000 100000\n-1.0\n" << std::string(64, '\0');
  try {
    io::readPfm(pfm);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("100000x100000"), std::string::npos) << e.what();
  }
  const std::string short_pfm = tempPath("short.pfm");
  std::ofstream(short_pfm, std::ios::binary) << "Pf\n4 4\n-1.0\n" << std::string(63, '\0');  // needs 64
  try {
    io::readPfm(short_pfm);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("64 bytes, but 63 bytes of data are left"), std::string::npos) << e.what();
  }
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

  const std::string only_p =
      "K: [0, 0, 0, 0, 0, 0, 0, 0, 0]\nP:\n- 500\n- 0\n- 310\n- 0\n- 0\n- 502\n- 230\n- 0\n- 0\n- 0\n- 1\n- 0\n";
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

// The layout camera_calibration_parsers writes (e.g. ~/.ros/camera_info/<name>.yaml, the calibrator's ost.yaml).
const char* kRosCalibrationFile =
    "image_width: 640\n"
    "image_height: 480\n"
    "camera_name: rgb_PS1080_PrimeSense\n"
    "camera_matrix:\n"
    "  rows: 3\n"
    "  cols: 3\n"
    "  data: [517.3, 0., 318.6, 0., 516.5, 255.3, 0., 0., 1.]\n"
    "distortion_model: plumb_bob\n"
    "distortion_coefficients:\n"
    "  rows: 1\n"
    "  cols: 5\n"
    "  data: [0.2624, -0.9531, -0.0054, 0.0026, 1.1633]\n"
    "rectification_matrix:\n"
    "  rows: 3\n"
    "  cols: 3\n"
    "  data: [1., 0., 0., 0., 1., 0., 0., 0., 1.]\n"
    "projection_matrix:\n"
    "  rows: 3\n"
    "  cols: 4\n"
    "  data: [510.0, 0., 320.0, 0., 0., 511.0, 250.0, 0., 0., 0., 1., 0.]\n";

TEST(CameraInfo, LoadsRosCalibrationFile) {
  const std::string path = tempPath("rgb_PS1080_PrimeSense.yaml");
  std::ofstream(path) << kRosCalibrationFile;
  const io::CameraInfo info = io::loadCameraInfo(path);
  EXPECT_EQ(info.intrinsics.fx, 517.3);
  EXPECT_EQ(info.intrinsics.fy, 516.5);
  EXPECT_EQ(info.intrinsics.cx, 318.6);
  EXPECT_EQ(info.intrinsics.cy, 255.3);
  EXPECT_EQ(info.width, 640);
  EXPECT_EQ(info.height, 480);

  // With an all-zero camera_matrix (uncalibrated), the projection_matrix is used.
  std::string zero_k = kRosCalibrationFile;
  const std::string k_data = "[517.3, 0., 318.6, 0., 516.5, 255.3, 0., 0., 1.]";
  zero_k.replace(zero_k.find(k_data), k_data.size(), "[0., 0., 0., 0., 0., 0., 0., 0., 0.]");
  const io::CameraInfo from_p = io::parseCameraInfoYaml(zero_k, "zero_k.yaml");
  EXPECT_EQ(from_p.intrinsics.fx, 510.0);
  EXPECT_EQ(from_p.intrinsics.fy, 511.0);
  EXPECT_EQ(from_p.intrinsics.cx, 320.0);
  EXPECT_EQ(from_p.intrinsics.cy, 250.0);
}

TEST(CameraInfo, BadMatricesAndSyntaxNameTheFileAndEntry) {
  // camera_matrix with 8 numbers and no projection matrix.
  std::string short_k =
      std::string(kRosCalibrationFile).substr(0, std::string(kRosCalibrationFile).find("projection_matrix"));
  short_k.replace(short_k.find(", 0., 0., 1.]"), 13, ", 0., 1.]");
  try {
    io::parseCameraInfoYaml(short_k, "short.yaml");
    FAIL() << "accepted a camera_matrix with 8 numbers";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("short.yaml"), std::string::npos) << what;
    EXPECT_NE(what.find("'camera_matrix'"), std::string::npos) << what;
    EXPECT_NE(what.find("8 numbers"), std::string::npos) << what;
  }
  try {
    io::parseCameraInfoYaml("K: [525, x, 319.5, 0, 525, 239.5, 0, 0, 1]\n", "letters.yaml");
    FAIL() << "accepted a non-number in K";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("letters.yaml"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("'x'"), std::string::npos) << e.what();
  }
  const std::string broken = tempPath("broken_camera.yaml");
  std::ofstream(broken) << "width: 640\nK: [525, 0, 319.5,\n  0, 525, 239.5\nheight: 480\n";
  try {
    io::loadCameraInfo(broken);
    FAIL() << "accepted an unclosed flow sequence";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(broken), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("line "), std::string::npos) << e.what();
  }
  try {
    io::parseCameraInfoYaml("width: wide\nK: [525, 0, 319.5, 0, 525, 239.5, 0, 0, 1]\n", "size.yaml");
    FAIL() << "accepted a non-numeric width";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("'width'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("wide"), std::string::npos) << e.what();
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
  bgr.at<cv::Vec3b>(0, 0) = {0, 0, 255};     // pure red
  bgr.at<cv::Vec3b>(0, 1) = {0, 255, 0};     // pure green
  bgr.at<cv::Vec3b>(0, 2) = {255, 0, 0};     // pure blue
  bgr.at<cv::Vec3b>(0, 3) = {51, 102, 204};  // mixed
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

namespace {

// Expects `call` to throw E whose message contains every one of `needles`.
template <typename E, typename F>
void expectThrowNaming(F call, const std::vector<std::string>& needles) {
  try {
    call();
    ADD_FAILURE() << "expected an exception naming " << needles.front();
  } catch (const E& e) {
    for (const std::string& needle : needles)
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << "'" << needle << "' not in: " << e.what();
  }
}

std::string writeTemp(const std::string& name, const std::string& text) {
  const std::string path = tempPath(name);
  std::ofstream(path) << text;
  return path;
}

}  // namespace

TEST(ConfigFile, JsonAndYamlSetFields) {
  const std::string json = writeTemp("config.json",
                                     "{\n  \"alpha\": 3.5,\n  \"initial_labels\": 12,\n  \"regularizer\": \"tv\",\n"
                                     "  \"detect_occlusions\": false\n}\n");
  Config a;
  io::applyConfigFile(json, a);
  EXPECT_EQ(a.alpha, 3.5);
  EXPECT_EQ(a.initial_labels, 12);
  EXPECT_EQ(a.regularizer, Regularizer::TotalVariation);
  EXPECT_FALSE(a.detect_occlusions);

  // One-line JSON with exponent notation.
  const std::string compact = writeTemp("compact.json", "{\"lambda_tv\":2.5e-1,\"outer_iterations\":4}");
  Config c;
  io::applyConfigFile(compact, c);
  EXPECT_EQ(c.lambda_tv, 0.25);
  EXPECT_EQ(c.outer_iterations, 4);

  const std::string yaml = writeTemp("config.yaml",
                                     "%YAML 1.2\n---\n# solver settings\nalpha: 1.25   # weight\ninitial_labels: 9\n"
                                     "regularizer: 'quad'\ndetect_occlusions: true\n");
  Config b;
  b.detect_occlusions = false;
  io::applyConfigFile(yaml, b);
  EXPECT_EQ(b.alpha, 1.25);
  EXPECT_EQ(b.initial_labels, 9);
  EXPECT_EQ(b.regularizer, Regularizer::Quadratic);
  EXPECT_TRUE(b.detect_occlusions);

  // A file with only comments changes nothing.
  const std::string empty = writeTemp("empty.yaml", "# nothing set here\n");
  Config d, defaults;
  io::applyConfigFile(empty, d);
  EXPECT_EQ(d.fields(), defaults.fields());
}

TEST(ConfigFile, ParsesKeyValuesInFileOrder) {
  const auto pairs = io::parseFlatKeyValues("{\"b\": 1, \"a\": \"x y\", \"c\": true}", "text");
  ASSERT_EQ(pairs.size(), 3u);
  EXPECT_EQ(pairs[0], (std::pair<std::string, std::string>{"b", "1"}));
  EXPECT_EQ(pairs[1], (std::pair<std::string, std::string>{"a", "x y"}));
  EXPECT_EQ(pairs[2], (std::pair<std::string, std::string>{"c", "true"}));
}

TEST(ConfigFile, ErrorsNameFileAndKey) {
  const std::string path = writeTemp("bad_config.yaml", "alpha: 2\nno_such_field: 1\n");
  Config c;
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(path, c); }, {path, "no_such_field"});
  const std::string bad_value = writeTemp("bad_value.yaml", "alpha: fast\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(bad_value, c); }, {bad_value, "alpha", "fast"});
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(tempPath("no_such_config.yaml"), c); },
                                 {"no_such_config.yaml", "does not exist"});
}

TEST(ConfigFile, NestedMissingAndRepeatedValuesNameFileKeyAndLine) {
  Config c;
  const std::string nested_json = writeTemp("nested.json", "{\n  \"lambda_tv\": 1,\n  \"alpha\": {\"x\": 1}\n}\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(nested_json, c); }, {nested_json, "'alpha'", "line 3"});
  const std::string nested_yaml = writeTemp("nested.yaml", "alpha: 1\nsolver:\n  lambda_tv: 2\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(nested_yaml, c); }, {nested_yaml, "'solver'", "line 2"});
  const std::string list_value = writeTemp("list.yaml", "alpha: [1, 2]\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(list_value, c); }, {list_value, "'alpha'", "nested"});
  const std::string no_value = writeTemp("no_value.yaml", "alpha:\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(no_value, c); }, {no_value, "'alpha'", "no value"});
  const std::string twice = writeTemp("twice.yaml", "alpha: 1\nlambda_tv: 2\nalpha: 3\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(twice, c); }, {twice, "'alpha'", "twice", "line 3"});
  const std::string list = writeTemp("top_list.yaml", "- alpha\n- 1\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(list, c); }, {list, "mapping"});
}

TEST(ConfigFile, MalformedFilesNameFileAndLine) {
  Config c;
  const std::string unclosed = writeTemp("unclosed.json", "{\n  \"alpha\": 1,\n  \"lambda_tv\": 2\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(unclosed, c); }, {unclosed, "line "});
  const std::string bad_indent = writeTemp("bad_indent.yaml", "alpha: 1\n  lambda_tv: 2\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(bad_indent, c); }, {bad_indent, "line 2"});
  const std::string unclosed_list = writeTemp("unclosed_list.yaml", "alpha: 1\nregularizer: [tv\n");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(unclosed_list, c); }, {unclosed_list, "line "});
  const std::string double_comma = writeTemp("double_comma.json", "{\"alpha\": 1,, \"lambda_tv\": 2}");
  expectThrowNaming<ConfigError>([&] { io::applyConfigFile(double_comma, c); }, {double_comma, "line 1"});
  EXPECT_EQ(c.alpha, Config().alpha) << "a malformed file must not half-apply";
}

// ----------------------------------------------------------------------------------------- JSON outputs

namespace {

Result resultWithTwoSegments() {
  Result r;
  r.width = 64;
  r.height = 48;
  r.processing_width = 32;
  r.processing_height = 24;
  r.pyramid_levels = 3;
  r.intrinsics = {52.5, 52.75, 31.5, 23.5};
  r.backend = "cpu";
  r.backend_note = "forced";
  r.energy = 123.25;
  r.timings.motion = 4.5;
  r.timings.total = 10.0;
  for (int i = 0; i < 2; ++i) {
    Segment s;
    s.id = i + 1;
    s.twist << 0.01 * (i + 1), -0.02, 0.03, 0.0, 0.1 * i, 0.0;
    s.transform = se3Exp(s.twist);
    s.support = 100.5 + i;
    s.centroid = Eigen::Vector3d(0.1 * i, -0.2, 1.5 + i);
    r.segments.push_back(s);
  }
  r.segments[1].centroid.x() = std::nan("");  // e.g. a segment without valid points
  r.segments[0].covariance = Matrix6d::Identity() * 1e-6;
  r.segments[0].covariance(0, 5) = r.segments[0].covariance(5, 0) = 2e-7;
  r.world.found = true;
  r.world.ids = {2};
  r.world.labels = {1};
  r.world.twist << 0.001, 0.002, -0.003, 0.01, -0.02, 0.0;
  r.world.covariance = Matrix6d::Identity() * 4e-6;
  r.world.pixels = 812.5;
  r.world.chosen_by = "widest";
  OuterIterationStats it;
  it.iteration = 0;
  it.labels_before = 4;
  it.labels_after = 2;
  it.merged = 2;
  it.energy = 150.0;
  it.label_change = 0.125;
  r.iterations.push_back(it);
  return r;
}

}  // namespace

TEST(Json, SegmentsParseBackWithEveryField) {
  const Result r = resultWithTwoSegments();
  const std::string path = writeTemp("segments.json", io::segmentsJson(r));
  const nlohmann::json j = io::readJsonFile(path);
  ASSERT_TRUE(j.contains("frame") && j.contains("units"));
  ASSERT_EQ(j.at("segments").size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const nlohmann::json& s = j["segments"][i];
    const Segment& expected = r.segments[i];
    EXPECT_EQ(s.at("id").get<int>(), expected.id);
    ASSERT_EQ(s.at("twist").size(), 6u);
    for (int k = 0; k < 6; ++k) EXPECT_EQ(s["twist"][k].get<double>(), expected.twist(k));
    ASSERT_EQ(s.at("transform").size(), 16u);
    for (int k = 0; k < 16; ++k) EXPECT_EQ(s["transform"][k].get<double>(), expected.transform(k / 4, k % 4));
    EXPECT_EQ(s.at("support").get<double>(), expected.support);
    EXPECT_NEAR(s.at("speed").get<double>(), expected.twist.head<3>().norm(), 1e-15);
    EXPECT_NEAR(s.at("rotation_angle").get<double>(), expected.twist.tail<3>().norm(), 1e-15);
    ASSERT_EQ(s.at("centroid").size(), 3u);
  }
  // The twist's covariance row-major, and which segment is the static world.
  ASSERT_EQ(j["segments"][0].at("covariance").size(), 36u);
  for (int k = 0; k < 36; ++k)
    EXPECT_EQ(j["segments"][0]["covariance"][k].get<double>(), r.segments[0].covariance(k / 6, k % 6));
  EXPECT_EQ(j["segments"][0]["covariance"][5].get<double>(), 2e-7);
  EXPECT_FALSE(j["segments"][0].at("world").get<bool>());
  EXPECT_TRUE(j["segments"][1].at("world").get<bool>());
  EXPECT_TRUE(j["segments"][1]["centroid"][0].is_null());  // NaN is written as null
  EXPECT_EQ(j["segments"][1]["centroid"][2].get<double>(), 2.5);
}

TEST(Json, ReportParsesBackWithConfigTimingsAndIterations) {
  const Result r = resultWithTwoSegments();
  Config config;
  config.alpha = 2.75;
  config.initial_labels = 7;
  config.regularizer = Regularizer::TotalVariation;
  io::RunInfo info;
  info.rgb1 = "dir/rgb \"1\".png";  // quotes must be escaped
  info.load_ms = 3.25;
  const nlohmann::json j = nlohmann::json::parse(io::reportJson(r, config, info));
  EXPECT_EQ(j.at("resolution").at("width").get<int>(), 64);
  EXPECT_EQ(j.at("processing_resolution").at("height").get<int>(), 24);
  EXPECT_EQ(j.at("pyramid_levels").get<int>(), 3);
  EXPECT_EQ(j.at("intrinsics").at("fy").get<double>(), 52.75);
  EXPECT_EQ(j.at("inputs").at("rgb1").get<std::string>(), info.rgb1);
  EXPECT_EQ(j.at("backend").get<std::string>(), "cpu");
  EXPECT_EQ(j.at("timings_ms").at("load").get<double>(), 3.25);
  EXPECT_EQ(j.at("timings_ms").at("motion").get<double>(), 4.5);
  EXPECT_EQ(j.at("final_energy").get<double>(), 123.25);
  EXPECT_EQ(j.at("segments").get<int>(), 2);
  const nlohmann::json& world = j.at("static_world");
  EXPECT_TRUE(world.at("found").get<bool>());
  EXPECT_EQ(world.at("chosen_by").get<std::string>(), "widest");
  EXPECT_EQ(world.at("ids").get<std::vector<int>>(), std::vector<int>{2});
  ASSERT_EQ(world.at("twist").size(), 6u);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(world["twist"][k].get<double>(), r.world.twist(k));
  ASSERT_EQ(world.at("covariance").size(), 36u);
  EXPECT_EQ(world["covariance"][0].get<double>(), 4e-6);
  EXPECT_EQ(world["covariance"][1].get<double>(), 0.0);
  EXPECT_EQ(world.at("pixels").get<double>(), 812.5);
  ASSERT_EQ(j.at("iterations").size(), 1u);
  EXPECT_EQ(j["iterations"][0].at("labels_before").get<int>(), 4);
  EXPECT_EQ(j["iterations"][0].at("label_change").get<double>(), 0.125);
  // Every Config field, typed: numbers and booleans bare, enumerations as strings.
  const nlohmann::json& c = j.at("config");
  EXPECT_EQ(c.size(), config.fields().size());
  EXPECT_EQ(c.at("alpha").get<double>(), 2.75);
  EXPECT_TRUE(c.at("initial_labels").is_number_integer());
  EXPECT_EQ(c.at("initial_labels").get<int>(), 7);
  EXPECT_TRUE(c.at("detect_occlusions").is_boolean());
  EXPECT_EQ(c.at("regularizer").get<std::string>(), "tv");
  // The report's config section is itself a valid config file that reproduces the Config.
  const std::string config_path = writeTemp("report_config.json", c.dump());
  Config back;
  io::applyConfigFile(config_path, back);
  EXPECT_EQ(back.fields(), config.fields());
}

TEST(Json, EvalWritesNullForMetricsWithoutSource) {
  io::EvalMetrics m;
  m.has_inputs = true;
  m.rmse_photometric = 0.0625;
  m.residual_pixels = 1234;
  m.segments = 3;
  m.flow_epe = 99.0;  // must not appear: has_ground_truth is false
  const std::string path = writeTemp("eval.json", io::evalJson(m));
  const nlohmann::json j = io::readJsonFile(path);
  EXPECT_FALSE(j.at("has_ground_truth").get<bool>());
  EXPECT_TRUE(j.at("has_inputs").get<bool>());
  EXPECT_TRUE(j.at("optical_flow_epe_px").is_null());
  EXPECT_TRUE(j.at("scene_flow_epe_m").is_null());
  EXPECT_EQ(j.at("rmse_photometric").get<double>(), 0.0625);
  EXPECT_EQ(j.at("residual_pixels").get<std::size_t>(), 1234u);
  EXPECT_EQ(j.at("segments").get<int>(), 3);
  for (const char* key : {"optical_flow_aae_deg", "optical_flow_epe_moving_px", "segmentation_agreement",
                          "occlusion_agreement", "rmse_geometric_zero_flow_m", "moving_pixels"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_TRUE(j.at("part_ids").is_null());
  m.has_ground_truth = true;
  m.flow_epe = std::nan("");  // e.g. no pixel could be scored
  m.part_ids = {{0, 1200, 3, 0.75}, {4, 90, 0, 0.0}};
  const nlohmann::json g = nlohmann::json::parse(io::evalJson(m));
  EXPECT_TRUE(g.at("optical_flow_epe_px").is_null());
  EXPECT_EQ(g.at("segmentation_agreement").get<double>(), 0.0);
  ASSERT_EQ(g.at("part_ids").size(), 2u);
  EXPECT_EQ(g.at("part_ids")[0].at("majority_id").get<int>(), 3);
  EXPECT_EQ(g.at("part_ids")[0].at("pixels").get<std::size_t>(), 1200u);
  EXPECT_EQ(g.at("part_ids")[0].at("share").get<double>(), 0.75);
  EXPECT_EQ(g.at("part_ids")[1].at("part").get<int>(), 4);
}

TEST(Json, GroundTruthSegmentsParseBack) {
  SyntheticPart part;
  part.id = 2;
  part.name = "box";
  part.twist << 0.05, 0, 0, 0, 0.1, 0;
  const nlohmann::json j = nlohmann::json::parse(io::groundTruthSegmentsJson({part}));
  ASSERT_EQ(j.at("parts").size(), 1u);
  EXPECT_EQ(j["parts"][0].at("name").get<std::string>(), "box");
  EXPECT_EQ(j["parts"][0].at("id").get<int>(), 2);
  EXPECT_EQ(j["parts"][0].at("twist")[4].get<double>(), 0.1);
  const Eigen::Matrix4d T = se3Exp(part.twist);
  EXPECT_EQ(j["parts"][0].at("transform")[3].get<double>(), T(0, 3));
  EXPECT_TRUE(j.contains("units"));
}

TEST(Json, ReadJsonFileNamesFileAndLineOfSyntaxErrors) {
  const std::string path = writeTemp("broken.json", "{\n  \"a\": 1,\n  \"b\": nan\n}\n");
  expectThrowNaming<InputError>([&] { io::readJsonFile(path); }, {path, "line 3"});
  expectThrowNaming<InputError>([&] { io::readJsonFile(tempPath("absent.json")); }, {"absent.json"});
}

TEST(Visualization, FlowColourWheelDirectionsAndInvalid) {
  ImageF flow(4, 1, 2, 0.f);
  flow(0, 0, 0) = 1.f;   // rightwards: red in the Middlebury coding
  flow(1, 0, 0) = -1.f;  // leftwards: cyan/blue
  flow(2, 0, 0) = std::nanf("");
  // pixel 3: zero flow -> white
  const cv::Mat image = io::flowColorImage(flow);
  const cv::Vec3b right = image.at<cv::Vec3b>(0, 0), left = image.at<cv::Vec3b>(0, 1);
  EXPECT_GT(right[2], 200);  // R
  EXPECT_LT(right[1], 60);   // G
  EXPECT_GT(left[0], 200);   // B
  EXPECT_LT(left[2], 60);    // R
  EXPECT_EQ(image.at<cv::Vec3b>(0, 2), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(image.at<cv::Vec3b>(0, 3), cv::Vec3b(255, 255, 255));
}

TEST(Visualization, SegmentationBlendsColoursOverImage) {
  SoftLabels u(2, 1, 3);  // two segments + outlier
  u.at(0, 0, 0) = 1.f;    // pixel 0: segment 0
  u.at(2, 1, 0) = 1.f;    // pixel 1: outlier
  ImageF grey(2, 1, 1, 0.5f);
  const cv::Mat image = io::segmentationImage(u, {7, 3}, grey);  // plane 0 is segment id 7
  const cv::Vec3b c7 = io::segmentColor(7), outlier = io::segmentColor(0);
  const Rgb8 palette7 = colourForId(7);
  EXPECT_EQ(c7, cv::Vec3b(palette7.b, palette7.g, palette7.r)) << "the core palette, in BGR order";
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(image.at<cv::Vec3b>(0, 0)[k], 0.6 * c7[k] + 0.4 * 127.5, 1.0);
    EXPECT_NEAR(image.at<cv::Vec3b>(0, 1)[k], 0.6 * outlier[k] + 0.4 * 127.5, 1.0);
  }
  EXPECT_NE(io::segmentColor(1), io::segmentColor(2));
  EXPECT_THROW(io::segmentationImage(u, {7}, grey), InputError);
}
