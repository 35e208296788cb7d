/**
 * @file bag_sequence.h
 * @brief An RGB-D sequence read from a rosbag, for `mcflow run-seq --bag`: colour and depth messages paired by
 * the nearest header stamp, converted by the nodelet's own conversion (toFrameInput, after the message
 * validation), so a bag gives the frames the nodelet would solve. No ROS type appears here: the tool includes
 * this header in every build and compiles the calls only where the ROS build is on (MCFLOW_WITH_ROSBAG).
 */
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "mc_flow/core/buffer_layout.h"
#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/ros/input_error.h"

namespace mc_flow_ros {

/// @brief The topics a bag is read from. A name without a leading '/' is taken as absolute (bags store
/// resolved names). Defaults: what the nodelet subscribes to under the camera namespace `camera` (launch/
/// mc_flow.launch) and what the demo bag (make_synthetic_bag) holds.
struct BagTopics {
  std::string rgb = "/camera/rgb/image_rect_color";           ///< sensor_msgs/Image, colour encodings
  std::string depth = "/camera/depth_registered/image_rect";  ///< sensor_msgs/Image, 16UC1 [mm] or 32FC1 [m]
  std::string info = "/camera/rgb/camera_info";               ///< sensor_msgs/CameraInfo of the colour camera
};

/// @brief How the frames are paired and converted.
struct BagReadOptions {
  BagTopics topics;
  /// [s] a colour message is paired with the depth message of the nearest header stamp when they differ by at
  /// most this much. Default 0.02 s: the nodelet's max_stamp_difference and TUM's associate.py; below half the
  /// frame interval of a 30 Hz camera, so a pair never takes a neighbouring frame's depth.
  double max_stamp_difference = 0.02;
  /// Intrinsics of the colour images [px]; empty: from the first message on `topics.info`.
  std::optional<mc_flow::Intrinsics> intrinsics;
  int downsample = 0;  ///< mc_flow::chooseDownsample's request (0: towards 320 px wide)
  double depth_range = mc_flow::Config().depth_downsample_range;  ///< [m] Config::depth_downsample_range
  std::uint64_t max_pixels = mc_flow::kDefaultMaxInputPixels;     ///< larger images are refused
};

/// @brief One paired frame at the processing resolution.
struct BagFrame {
  mc_flow::StreamFrame frame;        ///< stamp: the colour message's header stamp [s]; source: its frame_id
  mc_flow::ImageU8 colour;           ///< RGB at the processing resolution (pictures only)
  std::string rgb_name, depth_name;  ///< "BAG:TOPIC@STAMP" of the two messages (report.json's inputs)
};

/// @brief The frames of one bag (see the file comment). The bag stays open while the object lives; frames are
/// read on demand, so a long bag is never held in memory.
class BagSequence {
 public:
  /// @brief Opens `path` and pairs the messages. Frames follow the order of the colour messages in the bag (a
  /// recording across a driver restart keeps its stamps going back, and run-seq starts a new sequence there, as
  /// the nodelet does). Each colour message takes the depth message of the nearest header stamp within
  /// max_stamp_difference; a depth message claimed by several goes to the nearest (the earlier on a tie), the
  /// others stay unpaired. Throws mc_flow::InputError naming the value for: a missing or unreadable file, a
  /// topic with no message or of another type (the message lists the bag's topics), no camera_info when no
  /// intrinsics are given, an unusable first camera_info, no pair within the tolerance.
  BagSequence(const std::string& path, const BagReadOptions& options);
  ~BagSequence();
  BagSequence(const BagSequence&) = delete;
  BagSequence& operator=(const BagSequence&) = delete;

  /// @brief Paired frames.
  std::size_t size() const;
  /// @brief One line: the messages read, the frames paired, where the intrinsics come from.
  std::string summary() const;
  /// @brief Reads and converts frame `index` (< size()). Throws FrameInputError (its problem kind kept) naming
  /// the frame, its stamp and the bad value: an unsupported encoding, an inconsistent buffer, sizes, no valid
  /// depth.
  BagFrame frame(std::size_t index) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mc_flow_ros
