/**
 * @file message_validation.h
 * @brief Validation of incoming sensor_msgs before any library (cv_bridge, OpenCV) reads them: one
 * function per message type, in 64-bit arithmetic (mc_flow/core/buffer_layout.h). The nodelet's
 * conversions call them first; so must any other reader of messages (a bag reader).
 */
#pragma once

#include <cstdint>
#include <string>

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include "mc_flow/core/buffer_layout.h"
#include "mc_flow/ros/input_error.h"

namespace mc_flow_ros {

/// @brief What an image message is read as: the encodings accepted differ.
enum class ImageRole { Colour, Depth };

/// @brief Bytes of one channel value and channels per pixel of an accepted encoding.
struct EncodingLayout {
  int value_bytes = 0;
  int channels = 0;
};

/// @brief The layout of an encoding accepted for `role` (colour: rgb8 bgr8 rgba8 bgra8 mono8 mono16; depth:
/// 16UC1 32FC1); throws FrameInputError(Encoding) naming the encoding otherwise.
EncodingLayout encodingLayout(const std::string& encoding, ImageRole role);

/// @brief Throws FrameInputError naming every bad value unless the message is exactly consistent: an
/// accepted encoding; width, height > 0; width * height <= max_pixels; step >= width * bytes per pixel;
/// step a multiple of the value size; height * step == data.size() (no wrap); is_bigendian 0 or 1.
/// A big-endian message with multi-byte values is valid (the conversion swaps it). Returns the encoding's layout.
EncodingLayout validateImage(const sensor_msgs::Image& image, ImageRole role,
                             std::uint64_t max_pixels = mc_flow::kDefaultMaxInputPixels);

/// @brief The pinhole values of camera_info: from P (the rectified projection), or from K when P is all zero.
struct PinholeValues {
  double fx, fy, cx, cy;  ///< [px]
  bool from_k;
};
PinholeValues pinholeValues(const sensor_msgs::CameraInfo& info);

/// @brief Throws FrameInputError unless camera_info is usable: every K, R, P and D entry finite; a
/// positive focal length in P (or, when P is all zero, in K); width and height both zero (unknown) or both
/// > 0 with width * height <= max_pixels.
void validateCameraInfo(const sensor_msgs::CameraInfo& info,
                        std::uint64_t max_pixels = mc_flow::kDefaultMaxInputPixels);

/// @brief `image` with its multi-byte values in this machine's byte order (is_bigendian cleared).
sensor_msgs::Image toHostByteOrder(const sensor_msgs::Image& image, const EncodingLayout& layout);

/// @brief true when the message's byte order differs from this machine's and values have several bytes.
bool needsByteSwap(const sensor_msgs::Image& image, const EncodingLayout& layout);

}  // namespace mc_flow_ros
