/**
 * @file node_parameters.h
 * @brief The nodelet's own parameters (its private namespace) and their defaults, written once here. The
 * solver's parameters are mc_flow::Config's (dynamic_reconfigure). launch/mc_flow.launch passes every one of
 * these once, with the same default: test/ros/test_node_parameters.cpp checks it.
 */
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "mc_flow/core/buffer_layout.h"

namespace mc_flow_ros {

struct NodeParameters {
  int queue_size = 5;                            ///< [messages] queue of each input subscriber and of the synchroniser
  int max_input_pixels = int(mc_flow::kDefaultMaxInputPixels);  ///< [px] larger input images are refused
  bool approximate_sync = true;                  ///< approximate-time synchroniser; false: exact stamps
  double approximate_sync_max_interval = 0.0;    ///< [s] 0 = no limit
  int downsample = 0;                            ///< input pixels per processing pixel: 0 = automatic, or a power of two
  double max_stamp_difference = 0.02;           ///< [s] RGB vs depth stamps before a warning
  double max_pair_interval = 1.0;               ///< [s] a longer gap between frames starts a new sequence
  double no_input_warning_after = 5.0;          ///< [s] warn when subscribed inputs stay silent this long
  bool publish_tf = false;                      ///< one TF frame per segment
  std::string segment_frame_prefix = "mc_flow_segment_";  ///< TF child frame = prefix + segment id
  std::string odom_frame = "odom";              ///< ~odom's frame (REP 105): the camera's first pose
  std::string base_frame;                       ///< ~odom's child frame; "" = the colour camera's optical frame
  bool publish_odom_tf = false;                 ///< broadcast odom_frame -> base_frame (off when another node owns it)
  std::string prior_frame;                      ///< another odometry's fixed frame: TF prior_frame -> camera gives the
                                                ///< static world's prior per pair; "" = no prior
  std::string cloud_colour = "segment";         ///< rgb of ~scene_flow: segment or image
  double marker_seconds_ahead = 1.0;            ///< [s] length of the motion arrows in time
  double segmentation_blend = 0.6;              ///< weight of the segment colours over the image in ~segmentation
  bool print_summary = false;                   ///< log one line per solved pair
  std::string save_dir;                         ///< write PNGs per pair into this folder ("" = do not save)

  /// @brief Every parameter as (name, default as text), in declaration order.
  static std::vector<std::pair<std::string, std::string>> defaults();
};

}  // namespace mc_flow_ros
