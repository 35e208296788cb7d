/**
 * @file mc_flow_nodelet.h
 * @brief mc_flow/MCFlowNodelet: synchronised RGB-D in; segments, soft labels, occlusion, scene flow out.
 *
 * Thin shell around mc_flow::SequencePipeline (pairing, resets, warm starts, persistent segment ids and
 * tracks live there, shared with `mcflow run-seq`). The synchroniser callback only hands the newest frame
 * to a worker thread (frames arriving while a pair is being solved replace the waiting one and are counted
 * as dropped), so the camera's nodelet manager is never blocked by a solve. Each solved frame is paired
 * with the previously solved one. Inputs are subscribed only while an output has a listener.
 */
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/pass_through.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/sync_policies/exact_time.h>
#include <message_filters/synchronizer.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include "mc_flow/McFlowConfig.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/ros/conversions.h"
#include "mc_flow/ros/node_parameters.h"
#include "mc_flow/core/sequence.h"

namespace mc_flow_ros {

class MCFlowNodelet : public nodelet::Nodelet {
 public:
  MCFlowNodelet() = default;
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
  void readParameters();
  /// (Re)creates the synchroniser of the three inputs (approximate or exact time), fed by the gates.
  void createSynchroniser();
  /// Counts arrivals per topic (0 rgb, 1 depth, 2 camera_info) and gaps in header.seq (messages lost
  /// before the callback), and decides whether the message reaches the synchroniser: stamps that repeat
  /// or go back are held back, except that a jump back restarts the stream (at most every
  /// kMinSecondsBetweenRestarts), so the synchroniser only ever sees increasing stamps.
  bool admitInput(int topic, const std_msgs::Header& header);
  void logStartup();
  /// Subscribes the inputs while any output has a listener (or a demo option needs results).
  void connectCb();
  void syncCb(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::ImageConstPtr& depth,
              const sensor_msgs::CameraInfoConstPtr& info);
  void reconfigureCb(mc_flow::McFlowConfig& parameters, uint32_t level);
  void workerLoop();
  void process(const SyncedInput& input);
  void publish(const mc_flow::Result& result, const PairContext& pair);
  void publishTf(const mc_flow::Result& result, const PairContext& pair);
  // ~odom and the odom -> base TF (publish_odom_tf) from the pipeline's odometry, through the camera's mount.
  void publishOdometry(const PairContext& pair);
  // The camera's pose in prior_frame at the header's stamp (TF), or none (no prior_frame, or no transform: a throttled
  // warning).
  std::optional<Eigen::Matrix4d> cameraPosePrior(const std_msgs::Header& header);
  void saveAndSummarise(const mc_flow::Result& result, const PairContext& pair, const cv::Mat& segmentation);
  void timerCb(const ros::WallTimerEvent& event);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  /// Warns at most every `period` seconds per key (one key per distinct problem); the next warning of a
  /// key says how many were held back since. Counts every call per kind (the key up to its first ':')
  /// for the diagnostics, and remembers the text.
  void warnThrottled(const std::string& key, const std::string& text, double period = 5.0);
  /// Says once, at start-up, which backend solves (no GPU is normal: not a warning unless CUDA was asked for).
  void reportBackend(const mc_flow::Result& result);
  bool anyListener() const;

  // ---- parameters (private namespace; see logStartup and the README for units) ----
  NodeParameters params_;  // node_parameters.h: the defaults' one place
  CloudColour cloud_colour_ = CloudColour::Segment;  // params_.cloud_colour, parsed

  // ---- ROS interfaces ----
  ros::NodeHandle nh_, pnh_;
  std::unique_ptr<image_transport::ImageTransport> it_in_, it_out_;
  image_transport::SubscriberFilter rgb_sub_, depth_sub_;
  message_filters::Subscriber<CameraInfo> info_sub_;
  // Between the subscribers and the synchroniser: pass only what admitInput() lets through.
  message_filters::PassThrough<Image> rgb_gate_, depth_gate_;
  message_filters::PassThrough<CameraInfo> info_gate_;
  std::unique_ptr<message_filters::Synchronizer<ApproximatePolicy>> approximate_sync_ptr_;
  std::unique_ptr<message_filters::Synchronizer<ExactPolicy>> exact_sync_ptr_;
  image_transport::Publisher soft_labels_pub_, labels_pub_, segmentation_pub_, occlusion_pub_, moving_mask_pub_;
  ros::Publisher segments_pub_, cloud_pub_, markers_pub_, info_pub_, odom_pub_, camera_path_pub_;
  // ~camera_path: the camera's last poses (10 s at 30 Hz), oldest first.
  static constexpr std::size_t kCameraPathPoses = 300;
  std::deque<Eigen::Matrix4d> camera_poses_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;  // the camera's mount (base_frame set)
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<dynamic_reconfigure::Server<mc_flow::McFlowConfig>> reconfigure_server_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<diagnostic_updater::Updater> updater_;
  ros::WallTimer timer_;
  ros::WallTime last_restart_;  // last synchroniser restart (stats_mutex_)
  std::mutex connect_mutex_;
  std::atomic<bool> subscribed_{false};
  std::string rgb_topic_, depth_topic_, info_topic_;

  // ---- worker hand-over ----
  std::thread worker_;
  std::mutex pending_mutex_;
  std::condition_variable pending_cv_;
  std::optional<SyncedInput> pending_;
  bool stop_ = false;
  std::optional<mc_flow::Config> pending_config_;  // guarded by pending_mutex_
  bool sequence_break_ = false;                     // guarded by pending_mutex_: inputs were unsubscribed

  // ---- worker state (worker thread only) ----
  std::unique_ptr<mc_flow::SequencePipeline> pipeline_;
  mc_flow::Config solver_config_;  // the pipeline's
  bool backend_reported_ = false;
  long pair_index_ = 0;

  // ---- statistics (stats_mutex_) ----
  mutable std::mutex stats_mutex_;
  std::deque<ros::WallTime> sync_times_;   // arrivals of synchronised frames (last 10 s)
  ros::WallTime last_sync_time_, subscribed_since_;
  long frames_synced_ = 0, frames_dropped_ = 0, frames_skipped_ = 0, pairs_solved_ = 0, sequence_resets_ = 0;
  long warm_starts_ = 0, cold_fallbacks_ = 0;  // pairs by Result::start (the rest started cold)
  std::string last_start_;                      // the last pair's start kind and, for a fallback, why
  long rgb_count_ = 0, depth_count_ = 0, info_count_ = 0;
  ros::Time last_input_stamp_[3];   // last stamp admitted per topic (zero after a restart)
  std::uint32_t last_input_seq_[3] = {0, 0, 0};
  long lost_before_callback_[3] = {0, 0, 0};  // header.seq gaps
  long held_back_[3] = {0, 0, 0};             // repeated or backward stamps not passed to the synchroniser
  long synchroniser_restarts_ = 0;
  long sync_counts_[3] = {0, 0, 0};  // per-topic arrivals at the last synchronised frame
  long watch_counts_[3] = {0, 0, 0};  // timerCb: per-topic arrivals at its last tick
  ros::WallTime watch_last_arrival_[3];  // timerCb: when each count last changed (its resolution: 1 s)
  mc_flow::StageTimings last_timings_;
  double total_solve_ms_ = 0;
  std::string backend_, backend_note_, last_problem_;
  long backend_fallbacks_ = 0;           // BackendErrors that moved the pipeline to the CPU
  std::string last_backend_failure_;     // the latest one's message
  bool on_cpu_after_failure_ = false;    // until a pair is solved on the GPU again
  struct WarningState {
    ros::WallTime last_shown;
    long held_back = 0;  // since last_shown
  };
  std::map<std::string, WarningState> warnings_;
  std::map<std::string, long> warnings_per_kind_;
};

}  // namespace mc_flow_ros
