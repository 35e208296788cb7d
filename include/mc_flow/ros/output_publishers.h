/**
 * @file output_publishers.h
 * @brief The nodelet's outputs: advertises every topic, says whether any has a listener, and publishes a solved pair
 * on the topics that have one (outputs nobody subscribes to are not computed), plus the TF frames, ~odom and the
 * demo options (one summary line per pair, PNGs per pair). The messages themselves are made in conversions.h.
 */
#pragma once

#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <image_transport/image_transport.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>

#include "mc_flow/core/sequence.h"
#include "mc_flow/ros/conversions.h"
#include "mc_flow/ros/node_parameters.h"

namespace mc_flow_ros {

class OutputPublishers {
 public:
  /// A throttled warning (key, text), as NodeStatus::warning takes it.
  using Warn = std::function<void(const std::string& key, const std::string& text)>;

  /// @brief Advertises every output in `private_nh`'s namespace; `connect` is called whenever a listener comes or
  /// goes. `tf_buffer` (may be null when base_frame is empty) finds the camera's mount for ~odom. `logger`: the
  /// nodelet's name, for the summary lines.
  OutputPublishers(ros::NodeHandle& private_nh, image_transport::ImageTransport& transport,
                   const NodeParameters& params, const std::function<void()>& connect, tf2_ros::Buffer* tf_buffer,
                   std::string logger);

  bool anyListener() const;
  /// @brief The optional output images the next pair needs: the soft labels for ~soft_labels, ~segmentation or
  /// save_dir, the scene flow for ~scene_flow (issue: outputs nobody subscribes to are not downloaded).
  mc_flow::OutputSelection wantedOutputs() const;
  /// @brief The outputs' resolved names, for the start-up log.
  std::string topics() const;

  /// @brief Publishes `result` (the pair `pair`, solved by `pipeline`, the `pair_index`-th) on every output with a
  /// listener; `frames_dropped` goes into the summary line.
  void publish(const mc_flow::Result& result, const PairContext& pair, const mc_flow::SequencePipeline& pipeline,
               long pair_index, long frames_dropped, const Warn& warn);

  /// ~camera_path: the camera's last poses (10 s at 30 Hz).
  static constexpr std::size_t kCameraPathPoses = 300;

 private:
  void publishOdometry(const PairContext& pair, const mc_flow::Odometry& odometry, const Warn& warn);
  void saveAndSummarise(const mc_flow::Result& result, const PairContext& pair, const cv::Mat& segmentation,
                        long pair_index, long frames_dropped) const;

  const NodeParameters& params_;
  std::string logger_;
  CloudColour cloud_colour_;
  tf2_ros::Buffer* tf_buffer_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster_;
  image_transport::Publisher soft_labels_, labels_, segmentation_, occlusion_, moving_mask_;
  ros::Publisher segments_, cloud_, markers_, info_, odom_, camera_path_;
  // The image and cloud messages, reused once their subscribers let go of them (message_pool.h).
  ImagePool soft_labels_pool_, labels_pool_, segmentation_pool_, occlusion_pool_, moving_mask_pool_;
  CloudPool cloud_pool_;
  std::deque<Eigen::Matrix4d> camera_poses_;  // the last kCameraPathPoses, oldest first
};

}  // namespace mc_flow_ros
