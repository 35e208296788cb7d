#include "mc_flow/ros/message_validation.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <sensor_msgs/image_encodings.h>

namespace enc = sensor_msgs::image_encodings;

namespace mc_flow_ros {

namespace {

bool hostIsBigEndian() {
  const std::uint16_t probe = 1;
  return *reinterpret_cast<const std::uint8_t*>(&probe) == 0;
}

template <std::size_t N>
bool allFinite(const boost::array<double, N>& values) {
  return std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v); });
}

}  // namespace

EncodingLayout encodingLayout(const std::string& encoding, ImageRole role) {
  if (role == ImageRole::Colour) {
    if (encoding == enc::RGB8 || encoding == enc::BGR8) return {1, 3};
    if (encoding == enc::RGBA8 || encoding == enc::BGRA8) return {1, 4};
    if (encoding == enc::MONO8) return {1, 1};
    if (encoding == enc::MONO16) return {2, 1};
    throw FrameInputError(InputProblem::Encoding, "unsupported colour encoding '" + encoding +
                                                      "' (accepted: rgb8 bgr8 rgba8 bgra8 mono8 mono16)");
  }
  if (encoding == enc::TYPE_16UC1) return {2, 1};
  if (encoding == enc::TYPE_32FC1) return {4, 1};
  throw FrameInputError(InputProblem::Encoding,
                        "unsupported depth encoding '" + encoding + "' (accepted: 16UC1 in mm, 32FC1 in m)");
}

EncodingLayout validateImage(const sensor_msgs::Image& image, ImageRole role, std::uint64_t max_pixels) {
  const char* what = role == ImageRole::Colour ? "colour image" : "depth image";
  const EncodingLayout layout = encodingLayout(image.encoding, role);
  if (image.is_bigendian > 1) {
    throw FrameInputError(InputProblem::Layout, std::string(what) + " (" + image.encoding + "): is_bigendian is " +
                                                    std::to_string(int(image.is_bigendian)) + ", expected 0 or 1");
  }
  // A message's data must be exactly height * step bytes.
  const mc_flow::BufferLayout buffer{
      image.width,       image.height, std::uint64_t(layout.channels), std::uint64_t(layout.value_bytes), image.step,
      image.data.size(), true};
  const std::string problem = mc_flow::bufferLayoutProblem(buffer, max_pixels);
  if (!problem.empty()) {
    std::uint64_t pixels = 0;
    const bool too_large =
        image.width > 0 && image.height > 0 &&
        (!mc_flow::multiplyWithoutOverflow(image.width, image.height, pixels) || pixels > max_pixels);
    throw FrameInputError(
        too_large ? InputProblem::Size : InputProblem::Layout,
        std::string(what) + " (" + image.encoding + ", step " + std::to_string(image.step) + "): " + problem);
  }
  return layout;
}

PinholeValues pinholeValues(const sensor_msgs::CameraInfo& info) {
  const bool from_k = info.P[0] == 0 && info.P[5] == 0 && info.P[2] == 0 && info.P[6] == 0;
  if (from_k) return {info.K[0], info.K[4], info.K[2], info.K[5], true};
  return {info.P[0], info.P[5], info.P[2], info.P[6], false};
}

void validateCameraInfo(const sensor_msgs::CameraInfo& info, std::uint64_t max_pixels) {
  if (!allFinite(info.K) || !allFinite(info.R) || !allFinite(info.P) ||
      !std::all_of(info.D.begin(), info.D.end(), [](double v) { return std::isfinite(v); })) {
    throw FrameInputError(InputProblem::Intrinsics, "camera_info has a NaN or infinite entry in K, R, P or D");
  }
  const std::string size = std::to_string(info.width) + "x" + std::to_string(info.height);
  if ((info.width == 0) != (info.height == 0)) {
    throw FrameInputError(InputProblem::Size, "camera_info size " + size + ": one side is zero, the other not");
  }
  std::uint64_t pixels = 0;
  if (info.width > 0 && (!mc_flow::multiplyWithoutOverflow(info.width, info.height, pixels) || pixels > max_pixels)) {
    throw FrameInputError(InputProblem::Size, "camera_info size " + size + " exceeds the limit of " +
                                                  std::to_string(max_pixels) + " pixels");
  }
  const PinholeValues pinhole = pinholeValues(info);
  if (!(pinhole.fx > 0) || !(pinhole.fy > 0)) {
    std::ostringstream s;
    s << "camera_info has unusable intrinsics (fx=" << pinhole.fx << ", fy=" << pinhole.fy << " from "
      << (pinhole.from_k ? "K, P being all zero" : "P") << "): is the camera calibrated?";
    throw FrameInputError(InputProblem::Intrinsics, s.str());
  }
}

bool needsByteSwap(const sensor_msgs::Image& image, const EncodingLayout& layout) {
  return layout.value_bytes > 1 && bool(image.is_bigendian) != hostIsBigEndian();
}

sensor_msgs::Image toHostByteOrder(const sensor_msgs::Image& image, const EncodingLayout& layout) {
  sensor_msgs::Image out = image;
  out.is_bigendian = hostIsBigEndian();
  if (!needsByteSwap(image, layout)) return out;
  const std::size_t n = std::size_t(layout.value_bytes);
  // Rows may be padded; swapping the padding too is harmless (step is a multiple of the value size).
  for (std::size_t i = 0; i + n <= out.data.size(); i += n)
    std::reverse(out.data.begin() + i, out.data.begin() + i + n);
  return out;
}

}  // namespace mc_flow_ros
