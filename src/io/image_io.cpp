#include "mc_flow/io/image_io.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/io/flow_io.h"

namespace mc_flow {
namespace io {
namespace {

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

std::string describeType(const cv::Mat& m) {
  std::string depth;
  switch (m.depth()) {
    case CV_8U: depth = "8-bit unsigned"; break;
    case CV_8S: depth = "8-bit signed"; break;
    case CV_16U: depth = "16-bit unsigned"; break;
    case CV_16S: depth = "16-bit signed"; break;
    case CV_32S: depth = "32-bit integer"; break;
    case CV_32F: depth = "32-bit float"; break;
    case CV_64F: depth = "64-bit float"; break;
    default: depth = "unknown depth"; break;
  }
  return depth + ", " + std::to_string(m.channels()) + " channel(s)";
}

void requireReadable(const std::string& path, const std::string& what) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(what + " '" + path + "': file does not exist");
  if (!std::filesystem::is_regular_file(path, ec)) throw InputError(what + " '" + path + "': not a regular file");
}

cv::Mat readWithOpenCv(const std::string& path, int flags, const std::string& what) {
  requireReadable(path, what);
  cv::Mat image;
  try {
    image = cv::imread(path, flags);
  } catch (const cv::Exception& e) {
    throw InputError(what + " '" + path + "': OpenCV could not decode it (" + e.what() + ")");
  }
  if (image.empty()) throw InputError(what + " '" + path + "': unreadable or unsupported image format");
  return image;
}

}  // namespace

bool fileExists(const std::string& path) {
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}

ImageF intensityFromMat(const cv::Mat& image, const std::string& what) {
  double full_scale = 0;
  if (image.depth() == CV_8U)
    full_scale = 255.0;
  else if (image.depth() == CV_16U)
    full_scale = 65535.0;
  else if (image.depth() == CV_32F)
    full_scale = 1.0;  // float images are taken as already in [0, 1]
  else
    throw InputError(what + ": unsupported colour image type (" + describeType(image) + "); expected 8-bit or 16-bit");
  const int channels = image.channels();
  if (channels != 1 && channels != 3 && channels != 4)
    throw InputError(what + ": unsupported channel count " + std::to_string(channels) + "; expected 1, 3 or 4");

  cv::Mat as_float;
  image.convertTo(as_float, CV_MAKETYPE(CV_32F, channels), 1.0 / full_scale);
  ImageF out(image.cols, image.rows, 1);
  for (int y = 0; y < image.rows; ++y) {
    const float* row = as_float.ptr<float>(y);
    for (int x = 0; x < image.cols; ++x) {
      float v;
      if (channels == 1) {
        v = row[x];
      } else {  // OpenCV order: B, G, R
        const float* p = row + std::size_t(x) * channels;
        v = float(greyFromRgb(p[2], p[1], p[0]));
      }
      out(x, y) = std::clamp(v, 0.f, 1.f);
    }
  }
  return out;
}

ImageF depthFromMat(const cv::Mat& image, double depth_scale, const std::string& what) {
  if (image.channels() != 1)
    throw InputError(
        what + ": unsupported depth image type (" + describeType(image) +
        "); expected one channel of 16-bit unsigned (depth-scale units per metre) or 32-bit float (metres)");
  ImageF out(image.cols, image.rows, 1);
  if (image.depth() == CV_16U) {
    if (!(depth_scale > 0) || !std::isfinite(depth_scale))
      throw InputError(what + ": depth scale must be > 0, got " + std::to_string(depth_scale));
    for (int y = 0; y < image.rows; ++y) {
      const std::uint16_t* row = image.ptr<std::uint16_t>(y);
      for (int x = 0; x < image.cols; ++x) out(x, y) = float(row[x] / depth_scale);
    }
  } else if (image.depth() == CV_32F) {
    for (int y = 0; y < image.rows; ++y) {
      const float* row = image.ptr<float>(y);
      for (int x = 0; x < image.cols; ++x) out(x, y) = row[x];
    }
  } else {
    throw InputError(what + ": unsupported depth image type (" + describeType(image) +
                     "); expected 16-bit unsigned (depth-scale units per metre) or 32-bit float (metres)");
  }
  return out;
}

ImageF loadIntensity(const std::string& path, ImageU8* rgb) {
  const std::string what = "colour image '" + path + "'";
  cv::Mat image = readWithOpenCv(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "colour image");
  ImageF intensity = intensityFromMat(image, what);
  if (rgb) {
    cv::Mat bgr8;
    cv::Mat eight = image;
    if (image.depth() != CV_8U)
      image.convertTo(eight, CV_MAKETYPE(CV_8U, image.channels()), image.depth() == CV_16U ? 1.0 / 257.0 : 255.0);
    if (eight.channels() == 1)
      cv::cvtColor(eight, bgr8, cv::COLOR_GRAY2RGB);
    else if (eight.channels() == 4)
      cv::cvtColor(eight, bgr8, cv::COLOR_BGRA2RGB);
    else
      cv::cvtColor(eight, bgr8, cv::COLOR_BGR2RGB);
    *rgb = ImageU8(bgr8.cols, bgr8.rows, 3);
    for (int y = 0; y < bgr8.rows; ++y)
      std::copy_n(bgr8.ptr<std::uint8_t>(y), std::size_t(bgr8.cols) * 3, &(*rgb)(0, y));
  }
  return intensity;
}

ImageF loadDepth(const std::string& path, double depth_scale) {
  const std::string what = "depth image '" + path + "'";
  ImageF depth;
  if (lowerExtension(path) == ".pfm") {
    requireReadable(path, "depth image");
    depth = readPfm(path);
    if (depth.channels != 1)
      throw InputError(what + ": PFM depth must have one channel, found " + std::to_string(depth.channels));
  } else {
    cv::Mat image = readWithOpenCv(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "depth image");
    depth = depthFromMat(image, depth_scale, what);
  }
  const bool any_valid = std::any_of(depth.data.begin(), depth.data.end(), [](float z) { return isValidDepth(z); });
  if (!any_valid) throw InputError(what + ": no valid depth (every pixel is 0 or not finite)");
  return depth;
}

RgbdFrame loadRgbdFrame(const std::string& color_path, const std::string& depth_path, double depth_scale,
                        ImageU8* rgb) {
  RgbdFrame frame;
  frame.intensity = loadIntensity(color_path, rgb);
  frame.depth = loadDepth(depth_path, depth_scale);
  if (!frame.depth.sameSize(frame.intensity)) {
    std::ostringstream msg;
    msg << "image size mismatch: colour image '" << color_path << "' is " << frame.intensity.width << "x"
        << frame.intensity.height << " but depth image '" << depth_path << "' is " << frame.depth.width << "x"
        << frame.depth.height;
    throw InputError(msg.str());
  }
  return frame;
}

cv::Mat toMat(const ImageF& image) {
  cv::Mat m(image.height, image.width, CV_MAKETYPE(CV_32F, image.channels));
  for (int y = 0; y < image.height; ++y)
    std::copy_n(image.ptr() + std::size_t(y) * image.width * image.channels, std::size_t(image.width) * image.channels,
                m.ptr<float>(y));
  return m;
}

cv::Mat toMat(const ImageU8& image) {
  cv::Mat m(image.height, image.width, CV_MAKETYPE(CV_8U, image.channels));
  for (int y = 0; y < image.height; ++y)
    std::copy_n(image.ptr() + std::size_t(y) * image.width * image.channels, std::size_t(image.width) * image.channels,
                m.ptr<std::uint8_t>(y));
  return m;
}

ImageF toImageF(const cv::Mat& mat) {
  cv::Mat f;
  mat.convertTo(f, CV_MAKETYPE(CV_32F, mat.channels()));
  ImageF out(f.cols, f.rows, f.channels());
  for (int y = 0; y < f.rows; ++y)
    std::copy_n(f.ptr<float>(y), std::size_t(f.cols) * f.channels(),
                out.ptr() + std::size_t(y) * f.cols * f.channels());
  return out;
}

void writeImage(const std::string& path, const cv::Mat& image) {
  bool ok = false;
  try {
    ok = cv::imwrite(path, image);
  } catch (const cv::Exception& e) {
    throw FileError("cannot write '" + path + "': " + e.what());
  }
  if (!ok) throw FileError("cannot write '" + path + "' (directory missing, not writable, or format unsupported)");
}

void saveDepthPng16(const std::string& path, const ImageF& depth, double depth_scale) {
  cv::Mat m(depth.height, depth.width, CV_16UC1);
  for (int y = 0; y < depth.height; ++y)
    for (int x = 0; x < depth.width; ++x) {
      const float z = depth(x, y);
      const double units = isValidDepth(z) ? std::round(z * depth_scale) : 0.0;
      m.at<std::uint16_t>(y, x) = units > 65535.0 ? 0 : std::uint16_t(units);
    }
  writeImage(path, m);
}

void saveRgb(const std::string& path, const ImageU8& rgb) {
  cv::Mat m = toMat(rgb);
  if (rgb.channels == 3) cv::cvtColor(m, m, cv::COLOR_RGB2BGR);
  writeImage(path, m);
}

void saveMask(const std::string& path, const ImageU8& mask) { writeImage(path, toMat(mask)); }

void saveLabels(const std::string& path, const ImageI32& labels) {
  int max_id = 0;
  for (std::int32_t v : labels.data) max_id = std::max<int>(max_id, v);
  const bool eight_bit = max_id <= 255;
  cv::Mat m(labels.height, labels.width, eight_bit ? CV_8UC1 : CV_16UC1);
  for (int y = 0; y < labels.height; ++y)
    for (int x = 0; x < labels.width; ++x) {
      const int v = std::clamp<int>(labels(x, y), 0, 65535);
      if (eight_bit)
        m.at<std::uint8_t>(y, x) = std::uint8_t(v);
      else
        m.at<std::uint16_t>(y, x) = std::uint16_t(v);
    }
  writeImage(path, m);
}

ImageI32 loadLabels(const std::string& path) {
  cv::Mat m = readWithOpenCv(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE, "label image");
  if (m.depth() != CV_8U && m.depth() != CV_16U)
    throw InputError("label image '" + path + "': expected 8- or 16-bit, found " + describeType(m));
  ImageI32 out(m.cols, m.rows, 1);
  for (int y = 0; y < m.rows; ++y)
    for (int x = 0; x < m.cols; ++x)
      out(x, y) = m.depth() == CV_8U ? m.at<std::uint8_t>(y, x) : m.at<std::uint16_t>(y, x);
  return out;
}

ImageU8 loadMask(const std::string& path) {
  cv::Mat m = readWithOpenCv(path, cv::IMREAD_GRAYSCALE, "mask image");
  ImageU8 out(m.cols, m.rows, 1);
  for (int y = 0; y < m.rows; ++y) std::copy_n(m.ptr<std::uint8_t>(y), m.cols, &out(0, y));
  return out;
}

}  // namespace io
}  // namespace mc_flow
