/**
 * @file mc_flow_nodelet.h
 * @brief mc_flow/MCFlowNodelet: synchronised RGB-D in; segments, soft labels, occlusion, scene flow, odometry out.
 *
 * A thin shell around mc_flow::SequencePipeline (pairing, resets, warm starts, persistent segment ids, tracks and
 * odometry live there, shared with `mcflow run-seq`). Its parts: the parameters (node_parameters.def), the input
 * subscribers and their transport (input_subscription.h), the inputs' gate and watch (input_gate.h), the outputs
 * (output_publishers.h), the counters and throttled warnings (node_status.h), what is said once (startup_report.h). The
 * synchroniser callback only hands the newest frame to a worker thread (frames arriving while a pair is being solved
 * replace the waiting one and are counted as dropped), so the camera's nodelet manager is never blocked by a solve.
 * Inputs are subscribed only while an output has a listener.
 */
#pragma once

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <message_filters/pass_through.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/sync_policies/exact_time.h>
#include <message_filters/synchronizer.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include "mc_flow/McFlowConfig.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/ros/input_gate.h"
#include "mc_flow/ros/input_subscription.h"
#include "mc_flow/ros/node_parameters.h"
#include "mc_flow/ros/node_status.h"
#include "mc_flow/ros/output_publishers.h"

namespace mc_flow_ros {

class MCFlowNodelet : public nodelet::Nodelet {
 public:
  MCFlowNodelet() = default;
  /// @brief For a process that hosts the nodelet itself: its solvers' backends come from `make_backend`
  /// (mc_flow::SolveBackendFactory; the tests inject GPU faults this way).
  explicit MCFlowNodelet(mc_flow::SolveBackendFactory make_backend) : make_backend_(std::move(make_backend)) {}
  ~MCFlowNodelet() override;

 private:
  using Image = sensor_msgs::Image;
  using CameraInfo = sensor_msgs::CameraInfo;
  using ApproximatePolicy = message_filters::sync_policies::ApproximateTime<Image, Image, CameraInfo>;
  using ExactPolicy = message_filters::sync_policies::ExactTime<Image, Image, CameraInfo>;

  /// A synchronised triple waiting for the worker.
  struct SyncedInput {
    sensor_msgs::ImageConstPtr rgb, depth;
    sensor_msgs::CameraInfoConstPtr info;
  };

  void onInit() override;
  /// (Re)creates the synchroniser of the three inputs (approximate or exact time), fed by the gate.
  void createSynchroniser();
  /// A message on its way to the synchroniser (InputGate::admit).
  bool admit(int topic, const std_msgs::Header& header);
  /// Subscribes the inputs while any output has a listener (or a demo option needs results).
  void connectCb();
  void syncCb(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::ImageConstPtr& depth,
              const sensor_msgs::CameraInfoConstPtr& info);
  void reconfigureCb(mc_flow::McFlowConfig& parameters, uint32_t level);
  void workerLoop();
  void process(const SyncedInput& input);
  /// The camera's pose in prior_frame at the header's stamp (TF), or none (no prior_frame, or no transform: a
  /// throttled warning).
  std::optional<Eigen::Matrix4d> cameraPosePrior(const std_msgs::Header& header);
  void timerCb(const ros::WallTimerEvent& event);
  /// A throttled warning (NodeStatus::warning).
  void warn(const std::string& key, const std::string& text, double period = 5.0);
  /// Says once which backend solves (no GPU is normal: not a warning unless CUDA was asked for).
  void reportBackend(const mc_flow::Result& result);

  NodeParameters params_;
  mc_flow::SolveBackendFactory make_backend_;  // empty: mc_flow::makeSolveBackend

  // ---- ROS interfaces ----
  ros::NodeHandle nh_, pnh_;
  std::unique_ptr<InputSubscription> inputs_;
  std::unique_ptr<image_transport::ImageTransport> it_out_;
  // Between the subscribers and the synchroniser: pass only what the gate lets through.
  message_filters::PassThrough<Image> rgb_pass_, depth_pass_;
  message_filters::PassThrough<CameraInfo> info_pass_;
  std::unique_ptr<message_filters::Synchronizer<ApproximatePolicy>> approximate_sync_;
  std::unique_ptr<message_filters::Synchronizer<ExactPolicy>> exact_sync_;
  std::unique_ptr<InputGate> gate_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;  // the camera's mount (base_frame) and the prior (prior_frame)
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<OutputPublishers> outputs_;
  std::unique_ptr<dynamic_reconfigure::Server<mc_flow::McFlowConfig>> reconfigure_server_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<diagnostic_updater::Updater> updater_;
  ros::WallTimer timer_;
  std::mutex connect_mutex_;
  std::atomic<bool> subscribed_{false};
  NodeStatus status_;

  // ---- worker hand-over (pending_mutex_) ----
  std::thread worker_;
  std::mutex pending_mutex_;
  std::condition_variable pending_cv_;
  std::optional<SyncedInput> pending_;
  bool stop_ = false;
  std::optional<mc_flow::Config> pending_config_;
  bool sequence_break_ = false;  // inputs were unsubscribed: the next frame starts a new sequence

  // ---- worker state (worker thread only) ----
  std::unique_ptr<mc_flow::SequencePipeline> pipeline_;
  mc_flow::Config solver_config_;  // the pipeline's
  bool backend_reported_ = false;
};

}  // namespace mc_flow_ros
