#include "mc_flow/ros/mc_flow_nodelet.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <sstream>
#include <utility>

#include <cv_bridge/cv_bridge.h>
#include <image_transport/exception.h>

#include <geometry_msgs/TransformStamped.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <pluginlib/class_list_macros.hpp>
#include <tf2_eigen/tf2_eigen.h>
#include <visualization_msgs/MarkerArray.h>

#include "mc_flow/SegmentArray.h"
#include "mc_flow/core/error.h"
#include "mc_flow/ros/input_watch.h"
#include "mc_flow/ros/reconfigure.h"

namespace mc_flow_ros {

namespace {

/// A stream restarting (stamps jumping back) restarts the synchroniser at most this often; backward stamps
/// in between are held back, so a storm of them cannot keep re-arming message_filters' warnings.
constexpr double kMinSecondsBetweenRestarts = 5.0;

std::string stampText(const ros::Time& t) {
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%u.%09u", t.sec, t.nsec);
  return buffer;
}

/// Hints that select `transport` whatever the parameters say. image_transport::TransportHints reads its
/// transport from a parameter, `~image_transport` unless told otherwise; in a standalone nodelet `~` is this
/// nodelet's private namespace, so hints for the raw fallback would read the missing transport again. An
/// empty parameter name resolves to `nh`'s namespace itself, which is a dictionary or absent, never a
/// string, so the default given here is what is used.
image_transport::TransportHints transportHintsFor(const std::string& transport, const ros::NodeHandle& nh) {
  return image_transport::TransportHints(transport, ros::TransportHints(), nh, "");
}

}  // namespace

MCFlowNodelet::~MCFlowNodelet() {
  timer_.stop();
  {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    rgb_sub_.unsubscribe();
    depth_sub_.unsubscribe();
    info_sub_.unsubscribe();
  }
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    stop_ = true;
  }
  pending_cv_.notify_all();
  if (worker_.joinable()) worker_.join();
}

void MCFlowNodelet::onInit() {
  nh_ = getNodeHandle();
  pnh_ = getPrivateNodeHandle();
  readParameters();

  it_in_ = std::make_unique<image_transport::ImageTransport>(nh_);
  it_out_ = std::make_unique<image_transport::ImageTransport>(pnh_);
  rgb_topic_ = nh_.resolveName("rgb/image_rect_color");
  depth_topic_ = nh_.resolveName("depth_registered/image_rect");
  info_topic_ = nh_.resolveName("rgb/camera_info");

  createSynchroniser();
  // Every message passes admitInput() on its way to the synchroniser: per-topic arrival counts (the
  // "no synchronised input" warning names the silent topic), losses, and stamps that repeat or go back.
  rgb_sub_.registerCallback(boost::function<void(const sensor_msgs::ImageConstPtr&)>(
      [this](const sensor_msgs::ImageConstPtr& m) { if (admitInput(0, m->header)) rgb_gate_.add(m); }));
  depth_sub_.registerCallback(boost::function<void(const sensor_msgs::ImageConstPtr&)>(
      [this](const sensor_msgs::ImageConstPtr& m) { if (admitInput(1, m->header)) depth_gate_.add(m); }));
  info_sub_.registerCallback(boost::function<void(const sensor_msgs::CameraInfoConstPtr&)>(
      [this](const sensor_msgs::CameraInfoConstPtr& m) { if (admitInput(2, m->header)) info_gate_.add(m); }));

  // The solver config comes from dynamic_reconfigure (initial values: private parameters or the core's
  // defaults, see cfg/McFlow.cfg); the first callback happens inside the server's constructor path.
  reconfigure_server_ = std::make_unique<dynamic_reconfigure::Server<mc_flow::McFlowConfig>>(reconfigure_mutex_, pnh_);
  reconfigure_server_->setCallback(boost::bind(&MCFlowNodelet::reconfigureCb, this, boost::placeholders::_1, boost::placeholders::_2));

  updater_ = std::make_unique<diagnostic_updater::Updater>(nh_, pnh_, getName());
  updater_->setHardwareID("mc_flow:" + rgb_topic_);
  updater_->add("MC-Flow", this, &MCFlowNodelet::diagnose);

  if (params_.publish_tf || params_.publish_odom_tf) tf_broadcaster_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  if (!params_.base_frame.empty() || !params_.prior_frame.empty()) {
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_);
  }

  worker_ = std::thread(&MCFlowNodelet::workerLoop, this);

  {
    // Hold the lock while advertising: a connect callback must not subscribe before everything exists.
    std::lock_guard<std::mutex> lock(connect_mutex_);
    auto image_connect = boost::bind(&MCFlowNodelet::connectCb, this);
    auto connect = [this](const ros::SingleSubscriberPublisher&) { connectCb(); };
    soft_labels_pub_ = it_out_->advertise("soft_labels", 1, image_connect, image_connect);
    labels_pub_ = it_out_->advertise("labels", 1, image_connect, image_connect);
    segmentation_pub_ = it_out_->advertise("segmentation", 1, image_connect, image_connect);
    occlusion_pub_ = it_out_->advertise("occlusion", 1, image_connect, image_connect);
    segments_pub_ = pnh_.advertise<mc_flow::SegmentArray>("segments", 5, connect, connect);
    cloud_pub_ = pnh_.advertise<sensor_msgs::PointCloud2>("scene_flow", 1, connect, connect);
    markers_pub_ = pnh_.advertise<visualization_msgs::MarkerArray>("motion_markers", 1, connect, connect);
    info_pub_ = pnh_.advertise<sensor_msgs::CameraInfo>("camera_info", 1, connect, connect);
    odom_pub_ = pnh_.advertise<nav_msgs::Odometry>("odom", 5, connect, connect);
    camera_path_pub_ = pnh_.advertise<nav_msgs::Path>("camera_path", 1, connect, connect);
    moving_mask_pub_ = it_out_->advertise("moving_mask", 1, image_connect, image_connect);
  }
  logStartup();
  connectCb();  // demo options (print_summary, save_dir, publish_tf) need results without listeners
  timer_ = nh_.createWallTimer(ros::WallDuration(1.0), &MCFlowNodelet::timerCb, this);
}

void MCFlowNodelet::createSynchroniser() {
  approximate_sync_ptr_.reset();
  exact_sync_ptr_.reset();
  if (params_.approximate_sync) {
    ApproximatePolicy policy(params_.queue_size);
    policy.setReset(true);  // a bag restarting under /clock clears the queues instead of stalling them
    approximate_sync_ptr_ = std::make_unique<message_filters::Synchronizer<ApproximatePolicy>>(
        std::as_const(policy), rgb_gate_, depth_gate_, info_gate_);
    if (params_.approximate_sync_max_interval > 0) {
      approximate_sync_ptr_->setMaxIntervalDuration(ros::Duration(params_.approximate_sync_max_interval));
    }
    approximate_sync_ptr_->registerCallback(boost::bind(&MCFlowNodelet::syncCb, this, boost::placeholders::_1, boost::placeholders::_2, boost::placeholders::_3));
  } else {
    ExactPolicy policy(params_.queue_size);
    policy.setReset(true);
    exact_sync_ptr_ = std::make_unique<message_filters::Synchronizer<ExactPolicy>>(std::as_const(policy), rgb_gate_, depth_gate_, info_gate_);
    exact_sync_ptr_->registerCallback(boost::bind(&MCFlowNodelet::syncCb, this, boost::placeholders::_1, boost::placeholders::_2, boost::placeholders::_3));
  }
}

bool MCFlowNodelet::admitInput(int topic, const std_msgs::Header& header) {
  const std::string& name = topic == 0 ? rgb_topic_ : topic == 1 ? depth_topic_ : info_topic_;
  const ros::Time& stamp = header.stamp;
  ros::Time last;
  bool restart = false;
  long held = 0;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++(topic == 0 ? rgb_count_ : topic == 1 ? depth_count_ : info_count_);
    // roscpp numbers each message of a publisher: a gap of a few is what the subscriber queue dropped;
    // a large jump (publisher restarted, other publisher) is not counted.
    const std::uint32_t previous_seq = last_input_seq_[topic];
    if (previous_seq != 0 && header.seq > previous_seq + 1 && header.seq - previous_seq < 1000) {
      lost_before_callback_[topic] += long(header.seq - previous_seq - 1);
    }
    last_input_seq_[topic] = header.seq;
    last = last_input_stamp_[topic];
    if (last.isZero() || stamp > last) {
      last_input_stamp_[topic] = stamp;
      return true;
    }
    const ros::WallTime now = ros::WallTime::now();
    restart = stamp < last && (last_restart_.isZero() || (now - last_restart_).toSec() >= kMinSecondsBetweenRestarts);
    if (restart) {
      last_restart_ = now;
      ++synchroniser_restarts_;
      for (ros::Time& t : last_input_stamp_) t = ros::Time();
      last_input_stamp_[topic] = stamp;
    } else {
      held = ++held_back_[topic];
    }
  }
  const std::string what = name + ": stamp " + stampText(stamp) +
                           (stamp == last ? " repeats the previous message's" : " went back from " + stampText(last));
  if (restart) {
    // A driver restart or a bag replayed without /clock: the synchroniser's queues hold the old stream.
    // All callbacks of this nodelet are serialised, so rebuilding it here is safe.
    warnThrottled("input_stamp:restart " + name, what + ": restarting the synchroniser");
    createSynchroniser();
    return true;
  }
  warnThrottled("input_stamp:" + name, what + ": message held back from the synchroniser (" + std::to_string(held) +
                                           " on this topic so far)");
  return false;
}

void MCFlowNodelet::readParameters() {
  pnh_.param("queue_size", params_.queue_size, params_.queue_size);
  pnh_.param("max_input_pixels", params_.max_input_pixels, params_.max_input_pixels);
  pnh_.param("approximate_sync", params_.approximate_sync, params_.approximate_sync);
  pnh_.param("approximate_sync_max_interval", params_.approximate_sync_max_interval, params_.approximate_sync_max_interval);
  pnh_.param("downsample", params_.downsample, params_.downsample);
  pnh_.param("max_stamp_difference", params_.max_stamp_difference, params_.max_stamp_difference);
  pnh_.param("max_pair_interval", params_.max_pair_interval, params_.max_pair_interval);
  pnh_.param("no_input_warning_after", params_.no_input_warning_after, params_.no_input_warning_after);
  pnh_.param("publish_tf", params_.publish_tf, params_.publish_tf);
  pnh_.param("segment_frame_prefix", params_.segment_frame_prefix, params_.segment_frame_prefix);
  pnh_.param("odom_frame", params_.odom_frame, params_.odom_frame);
  pnh_.param("base_frame", params_.base_frame, params_.base_frame);
  pnh_.param("publish_odom_tf", params_.publish_odom_tf, params_.publish_odom_tf);
  pnh_.param("prior_frame", params_.prior_frame, params_.prior_frame);
  pnh_.param("cloud_colour", params_.cloud_colour, params_.cloud_colour);
  const std::string& cloud_colour = params_.cloud_colour;
  pnh_.param("marker_seconds_ahead", params_.marker_seconds_ahead, params_.marker_seconds_ahead);
  pnh_.param("segmentation_blend", params_.segmentation_blend, params_.segmentation_blend);
  pnh_.param("print_summary", params_.print_summary, params_.print_summary);
  pnh_.param("save_dir", params_.save_dir, params_.save_dir);

  if (params_.publish_odom_tf && params_.base_frame.empty())
    NODELET_WARN("publish_odom_tf without base_frame broadcasts %s -> the camera's optical frame, which usually has a "
                 "parent in the camera's TF tree already: set base_frame to the robot's base frame",
                 params_.odom_frame.c_str());
  if (!params_.prior_frame.empty() && params_.prior_frame == params_.odom_frame && params_.publish_odom_tf)
    NODELET_WARN("prior_frame '%s' is the odom_frame this node broadcasts: its own odometry would be its prior; set "
                 "prior_frame to another source's frame", params_.prior_frame.c_str());
  if (params_.downsample < 0 || (params_.downsample & (params_.downsample - 1)) != 0) {
    NODELET_WARN("downsample %d is not 0 (automatic) or a power of two; using 0", params_.downsample);
    params_.downsample = 0;
  }
  if (params_.queue_size < 1) {
    NODELET_WARN("queue_size %d is below 1; using 1", params_.queue_size);
    params_.queue_size = 1;
  }
  if (params_.max_input_pixels < 256) {
    NODELET_WARN("max_input_pixels %d is below 256; using 256", params_.max_input_pixels);
    params_.max_input_pixels = 256;
  }
  if (params_.downsample < 0) {
    NODELET_WARN("downsample %d is negative; using 0 (automatic)", params_.downsample);
    params_.downsample = 0;
  }
  if (cloud_colour == "image") {
    cloud_colour_ = CloudColour::Image;
  } else if (cloud_colour != "segment") {
    NODELET_WARN("cloud_colour '%s' is neither 'segment' nor 'image'; using 'segment'", cloud_colour.c_str());
  }
  params_.segmentation_blend = std::min(std::max(params_.segmentation_blend, 0.0), 1.0);
  if (!params_.save_dir.empty()) {
    std::error_code error;
    std::filesystem::create_directories(params_.save_dir, error);
    if (error || !std::filesystem::is_directory(params_.save_dir, error)) {
      NODELET_ERROR("save_dir '%s' cannot be created (%s); pictures will not be saved", params_.save_dir.c_str(),
                    error ? error.message().c_str() : "it exists and is not a folder");
      params_.save_dir.clear();
    }
  }
}

void MCFlowNodelet::logStartup() {
  std::ostringstream s;
  s << "MC-Flow nodelet " << getName() << " started.\n"
    << "  inputs (synchronised, " << (params_.approximate_sync ? "approximate" : "exact") << " time): " << rgb_topic_
    << ", " << depth_topic_ << ", " << info_topic_ << " (image_transport, parameter image_transport selects the transport)\n"
    << "  outputs: " << segments_pub_.getTopic() << ", " << soft_labels_pub_.getTopic() << ", " << labels_pub_.getTopic()
    << ", " << segmentation_pub_.getTopic() << ", " << occlusion_pub_.getTopic() << ", " << cloud_pub_.getTopic()
    << ", " << markers_pub_.getTopic() << ", " << info_pub_.getTopic() << ", " << odom_pub_.getTopic() << ", " << camera_path_pub_.getTopic() << ", "
    << moving_mask_pub_.getTopic() << (params_.publish_tf || params_.publish_odom_tf ? ", /tf" : "") << "\n"
    << "  node parameters: queue_size=" << params_.queue_size << " max_input_pixels=" << params_.max_input_pixels << " approximate_sync=" << params_.approximate_sync
    << " approximate_sync_max_interval=" << params_.approximate_sync_max_interval << " s downsample=" << params_.downsample
    << (params_.downsample == 0 ? " (automatic)" : "") << " max_stamp_difference=" << params_.max_stamp_difference
    << " s max_pair_interval=" << params_.max_pair_interval << " s no_input_warning_after=" << params_.no_input_warning_after
    << " s publish_tf=" << params_.publish_tf << " segment_frame_prefix=" << params_.segment_frame_prefix
    << " odom_frame=" << params_.odom_frame << " base_frame='" << params_.base_frame
    << "' publish_odom_tf=" << params_.publish_odom_tf << " prior_frame='" << params_.prior_frame << "'"
    << " cloud_colour=" << (cloud_colour_ == CloudColour::Image ? "image" : "segment")
    << " marker_seconds_ahead=" << params_.marker_seconds_ahead << " s segmentation_blend=" << params_.segmentation_blend
    << " print_summary=" << params_.print_summary << " save_dir='"
    << params_.save_dir << "'\n  solver parameters (dynamic_reconfigure):";
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    const mc_flow::Config config = pending_config_ ? *pending_config_ : mc_flow::Config();
    for (const auto& [name, value] : config.fields()) s << " " << name << "=" << value;
  }
  NODELET_INFO_STREAM(s.str());
}

bool MCFlowNodelet::anyListener() const {
  return soft_labels_pub_.getNumSubscribers() > 0 || labels_pub_.getNumSubscribers() > 0 ||
         segmentation_pub_.getNumSubscribers() > 0 || occlusion_pub_.getNumSubscribers() > 0 ||
         segments_pub_.getNumSubscribers() > 0 || cloud_pub_.getNumSubscribers() > 0 ||
         markers_pub_.getNumSubscribers() > 0 || info_pub_.getNumSubscribers() > 0 ||
         odom_pub_.getNumSubscribers() > 0 || moving_mask_pub_.getNumSubscribers() > 0 ||
         camera_path_pub_.getNumSubscribers() > 0;
}

void MCFlowNodelet::connectCb() {
  std::lock_guard<std::mutex> lock(connect_mutex_);
  const bool needed = anyListener() || params_.print_summary || !params_.save_dir.empty() || params_.publish_tf ||
                      params_.publish_odom_tf;
  if (needed && !subscribed_) {
    // The transport comes from ~image_transport. One whose plug-in is not installed would throw inside
    // image_transport and take the manager (and the camera) down: check first, fall back to raw.
    image_transport::TransportHints hints("raw", ros::TransportHints(), pnh_);
    const std::vector<std::string> loadable = it_in_->getLoadableTransports();
    if (std::find(loadable.begin(), loadable.end(), "image_transport/" + hints.getTransport()) == loadable.end()) {
      std::string available;
      for (const std::string& name : loadable) available += " " + name.substr(name.find('/') + 1);
      NODELET_ERROR("image_transport '%s' is not installed (installed:%s): install its plug-in package or set "
                    "~image_transport to one of those; subscribing with 'raw' instead",
                    hints.getTransport().c_str(), available.c_str());
      hints = transportHintsFor("raw", pnh_);
    }
    // One queue length for the subscribers and the synchroniser: a burst the synchroniser could hold
    // must not be dropped before it (the losses that remain show in diagnostics).
    const auto queue = std::uint32_t(params_.queue_size);
    try {
      rgb_sub_.subscribe(*it_in_, "rgb/image_rect_color", queue, hints);
      depth_sub_.subscribe(*it_in_, "depth_registered/image_rect", queue, hints);
    } catch (const image_transport::Exception& e) {
      // A plug-in that is declared and loads but cannot subscribe. An exception out of onInit would make
      // nodelet's loader destroy this nodelet after its callback queues (a crash): keep a plug-in's inside.
      rgb_sub_.unsubscribe();
      depth_sub_.unsubscribe();
      NODELET_ERROR("image_transport '%s' cannot subscribe (%s); subscribing with 'raw' instead",
                    hints.getTransport().c_str(), e.what());
      hints = transportHintsFor("raw", pnh_);
      rgb_sub_.subscribe(*it_in_, "rgb/image_rect_color", queue, hints);
      depth_sub_.subscribe(*it_in_, "depth_registered/image_rect", queue, hints);
    }
    info_sub_.subscribe(nh_, "rgb/camera_info", queue);
    subscribed_ = true;
    std::lock_guard<std::mutex> stats(stats_mutex_);
    subscribed_since_ = ros::WallTime::now();
    NODELET_DEBUG("an output has a listener: subscribed to the inputs");
  } else if (!needed && subscribed_) {
    rgb_sub_.unsubscribe();
    depth_sub_.unsubscribe();
    info_sub_.unsubscribe();
    subscribed_ = false;
    NODELET_DEBUG("no output has a listener: unsubscribed from the inputs");
    // The next frame after a pause must not be paired with one from before it: the worker starts a new
    // sequence (it owns the pipeline, so it is told through a flag).
    std::lock_guard<std::mutex> pending(pending_mutex_);
    pending_.reset();
    sequence_break_ = true;
  }
}

void MCFlowNodelet::syncCb(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::ImageConstPtr& depth,
                           const sensor_msgs::CameraInfoConstPtr& info) {
  const ros::WallTime now = ros::WallTime::now();
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++frames_synced_;
    last_sync_time_ = now;
    sync_counts_[0] = rgb_count_;
    sync_counts_[1] = depth_count_;
    sync_counts_[2] = info_count_;
    sync_times_.push_back(now);
    while (!sync_times_.empty() && (now - sync_times_.front()).toSec() > 10.0) sync_times_.pop_front();
  }
  const double stamp_difference = std::abs((rgb->header.stamp - depth->header.stamp).toSec());
  if (stamp_difference > params_.max_stamp_difference) {
    warnThrottled("stamps", "RGB stamp " + stampText(rgb->header.stamp) + " and depth stamp " +
                                stampText(depth->header.stamp) + " differ by " + std::to_string(stamp_difference) +
                                " s (> max_stamp_difference " + std::to_string(params_.max_stamp_difference) +
                                " s): motion between them biases the result; check the camera's sync settings");
  }
  bool dropped = false;
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    dropped = pending_.has_value();  // the worker is still busy: the waiting frame is replaced by this one
    pending_ = SyncedInput{rgb, depth, info};
  }
  if (dropped) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++frames_dropped_;
  }
  pending_cv_.notify_one();
}

void MCFlowNodelet::reconfigureCb(mc_flow::McFlowConfig& parameters, uint32_t /*level*/) {
  try {
    mc_flow::Config config = toCoreConfig(parameters);
    std::lock_guard<std::mutex> lock(pending_mutex_);
    pending_config_ = config;
  } catch (const std::exception& e) {
    NODELET_ERROR("rejected solver parameters, keeping the previous ones: %s", e.what());
  }
}

void MCFlowNodelet::workerLoop() {
  while (true) {
    SyncedInput input;
    {
      std::unique_lock<std::mutex> lock(pending_mutex_);
      pending_cv_.wait(lock, [this] { return stop_ || pending_.has_value(); });
      if (stop_) return;
      input = *pending_;
      pending_.reset();
      if (sequence_break_) {
        sequence_break_ = false;
        if (pipeline_) pipeline_->reset();
      }
      if (pending_config_) {
        const mc_flow::Config config = *pending_config_;
        pending_config_.reset();
        lock.unlock();
        try {
          // New parameters: a new solver; the sequence (previous frame, prior, ids) goes on.
          if (pipeline_)
            pipeline_->setConfig(config);
          else
            pipeline_ = std::make_unique<mc_flow::SequencePipeline>(config, 1, params_.max_pair_interval);
          solver_config_ = config;
          backend_reported_ = false;
        } catch (const std::exception& e) {
          NODELET_ERROR("cannot create the solver with these parameters (%s); %s", e.what(),
                        pipeline_ ? "keeping the previous solver" : "no frame is processed until they are fixed");
        }
      }
    }
    try {
      process(input);
    } catch (const std::exception& e) {
      // Nothing may end the worker: report and go on with the next frame.
      warnThrottled("unexpected", std::string("frame skipped after an unexpected error: ") + e.what());
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++frames_skipped_;
    }
  }
}

void MCFlowNodelet::process(const SyncedInput& input) {
  if (!pipeline_) return;
  FrameInput current;
  try {
    current = toFrameInput(*input.rgb, *input.depth, *input.info, params_.downsample, std::uint64_t(params_.max_input_pixels),
                           solver_config_.depth_downsample_range);
  } catch (const FrameInputError& e) {
    // Throttled per distinct problem (digits removed: the same fault in every frame is one key).
    std::string key = std::string(inputProblemName(e.problem)) + ":" + e.what();
    key.erase(std::remove_if(key.begin(), key.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); }),
              key.end());
    warnThrottled(key, std::string("frame ") + stampText(input.rgb->header.stamp) + " skipped: " + e.what());
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++frames_skipped_;
    return;
  }

  // The frame is already at the processing resolution (toFrameInput applies the core's downsampling rule):
  // the pipeline pairs, solves and tracks. The display data travel with the frame.
  mc_flow::StreamFrame frame;
  frame.frame = current.frame;
  frame.K = current.K;
  frame.stamp = current.header.stamp.toSec();
  frame.source = current.header.frame_id;
  frame.camera_pose_prior = cameraPosePrior(current.header);
  const ros::Time stamp = current.header.stamp;
  frame.extra = std::move(current);
  const ros::WallTime start = ros::WallTime::now();
  mc_flow::SequenceStep step;
  try {
    step = pipeline_->push(std::move(frame));
  } catch (const mc_flow::InputError& e) {
    warnThrottled("input", "frame " + stampText(stamp) + " skipped: " + e.what());
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++frames_skipped_;
    return;
  }
  const double solve_ms = (ros::WallTime::now() - start).toSec() * 1e3;
  if (!step.reset_key.empty()) {
    warnThrottled("reset:" + step.reset_key, "frame " + stampText(stamp) + ": " + step.reset_reason +
                                                 ": starting a new sequence");
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++sequence_resets_;
  }
  using Outcome = mc_flow::SequenceStep::Outcome;
  if (step.outcome == Outcome::RepeatedStamp) {
    warnThrottled("stamp", "frame skipped: stamp " + stampText(stamp) +
                               " repeats the previous frame's (is a driver or bag publishing duplicates?)");
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++frames_skipped_;
    return;
  }
  if (step.outcome == Outcome::Started) return;
  if (step.outcome == Outcome::PairFailed) {
    if (!step.backend_fallback.empty()) {
      // The pipeline has switched to the CPU: this happens once per backend, so the warning is never held
      // back (period 0; a GPU restored by new parameters may fail again and is reported again).
      warnThrottled("backend", "pair ending at " + stampText(stamp) + " skipped: " + step.problem +
                                   "; continuing on the CPU", 0.0);
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++backend_fallbacks_;
      last_backend_failure_ = step.problem;
      on_cpu_after_failure_ = true;
      backend_ = "cpu";
      backend_note_ = "fallback after a failure of the requested backend";
    } else {
      // Bad input or parameters that do not fit this input: the sequence goes on with the newer frame.
      warnThrottled("solver", "pair ending at " + stampText(stamp) + " skipped: " + step.problem);
    }
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++frames_skipped_;
    return;
  }

  const mc_flow::Result& result = *step.result;
  reportBackend(result);
  const FrameInput& first = std::any_cast<const FrameInput&>(step.first->extra);
  const FrameInput& second = std::any_cast<const FrameInput&>(step.second->extra);
  PairContext pair;
  pair.header = second.header;
  pair.previous_stamp = first.header.stamp;
  pair.previous = &first;
  pair.current = &second;
  pair.solve_time_ms = solve_ms;
  pair.world = &step.world_velocities;
  pair_index_ = step.pair_index;

  publish(result, pair);
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++pairs_solved_;
    warm_starts_ += result.start == mc_flow::StartKind::Warm ? 1 : 0;
    cold_fallbacks_ += result.start == mc_flow::StartKind::ColdFallback ? 1 : 0;
    last_start_ = mc_flow::toString(result.start) + (result.start_note.empty() ? "" : ": " + result.start_note);
    last_timings_ = result.timings;
    total_solve_ms_ += solve_ms;
    backend_ = result.backend;
    backend_note_ = result.backend_note;
    if (result.backend_kind == mc_flow::Backend::Cuda) on_cpu_after_failure_ = false;  // new parameters restored it
  }
}

void MCFlowNodelet::reportBackend(const mc_flow::Result& result) {
  if (backend_reported_) return;
  backend_reported_ = true;
  const mc_flow::Backend requested = solver_config_.backend;
  if (result.backend_kind == mc_flow::Backend::Cuda || requested == mc_flow::Backend::Cpu) {
    NODELET_INFO("solver backend: %s (%s)", result.backend.c_str(), result.backend_note.c_str());
  } else if (requested == mc_flow::Backend::Auto) {
    // The usual case on a machine without an NVIDIA GPU: the CUDA runtime's own words ("driver version is
    // insufficient") read as a request to upgrade a driver, so they go to debug level.
    NODELET_INFO("no usable NVIDIA GPU/driver found: running on the CPU");
    NODELET_DEBUG("CUDA detail: %s", result.backend_note.c_str());
  } else {
    NODELET_WARN("backend 'cuda' was requested but no usable NVIDIA GPU/driver was found: running on the CPU (%s)",
                 result.backend_note.c_str());
  }
}

void MCFlowNodelet::publish(const mc_flow::Result& result, const PairContext& pair) {
  if (segments_pub_.getNumSubscribers() > 0) segments_pub_.publish(makeSegmentArray(result, pair));
  if (soft_labels_pub_.getNumSubscribers() > 0) soft_labels_pub_.publish(makeSoftLabelsImage(result, pair));
  if (labels_pub_.getNumSubscribers() > 0) labels_pub_.publish(makeLabelsImage(result, pair));
  if (occlusion_pub_.getNumSubscribers() > 0) occlusion_pub_.publish(makeOcclusionImage(result, pair));
  cv::Mat segmentation;
  if (segmentation_pub_.getNumSubscribers() > 0 || !params_.save_dir.empty()) {
    segmentation = segmentationPicture(result, pair, params_.segmentation_blend);
  }
  if (segmentation_pub_.getNumSubscribers() > 0) {
    segmentation_pub_.publish(makeSegmentationImage(segmentation, pair));
  }
  if (cloud_pub_.getNumSubscribers() > 0) cloud_pub_.publish(makeSceneFlowCloud(result, pair, cloud_colour_));
  if (markers_pub_.getNumSubscribers() > 0) {
    markers_pub_.publish(makeMotionMarkers(result, pair, params_.marker_seconds_ahead));
  }
  if (info_pub_.getNumSubscribers() > 0) {
    sensor_msgs::CameraInfo info = processingCameraInfo(*pair.current);
    info_pub_.publish(info);
  }
  if (moving_mask_pub_.getNumSubscribers() > 0 && pair.world) {
    moving_mask_pub_.publish(makeMovingMaskImage(result, *pair.world, pair));
  }
  if (params_.publish_tf) publishTf(result, pair);
  if (odom_pub_.getNumSubscribers() > 0 || params_.publish_odom_tf) publishOdometry(pair);
  camera_poses_.push_back(pipeline_->odometry().pose);
  if (camera_poses_.size() > kCameraPathPoses) camera_poses_.pop_front();
  if (camera_path_pub_.getNumSubscribers() > 0) camera_path_pub_.publish(makeCameraPath(camera_poses_, pair.header));
  if (params_.print_summary || !params_.save_dir.empty()) saveAndSummarise(result, pair, segmentation);
}

std::optional<Eigen::Matrix4d> MCFlowNodelet::cameraPosePrior(const std_msgs::Header& header) {
  if (params_.prior_frame.empty()) return std::nullopt;
  try {
    // A short wait: the other source's TF usually arrives within a few milliseconds of the images.
    return tf2::transformToEigen(
               tf_buffer_->lookupTransform(params_.prior_frame, header.frame_id, header.stamp, ros::Duration(0.02)))
        .matrix();
  } catch (const tf2::TransformException& e) {
    warnThrottled("prior", "no static-world prior for frame " + stampText(header.stamp) + ": no transform from " +
                               "prior_frame '" + params_.prior_frame + "' to '" + header.frame_id + "': " + e.what());
    return std::nullopt;
  }
}

void MCFlowNodelet::publishOdometry(const PairContext& pair) {
  // The camera's mount on the base (REP 105: odometry of base_frame); without base_frame, the camera's optical frame.
  Eigen::Isometry3d base_from_camera = Eigen::Isometry3d::Identity();
  std::string child = pair.header.frame_id;
  if (!params_.base_frame.empty()) {
    try {
      base_from_camera = tf2::transformToEigen(
          tf_buffer_->lookupTransform(params_.base_frame, pair.header.frame_id, pair.header.stamp, ros::Duration(0.05)));
      child = params_.base_frame;
    } catch (const tf2::TransformException& e) {
      warnThrottled("odom_mount", "~odom not published: no transform from base_frame '" + params_.base_frame +
                                      "' to the camera frame '" + pair.header.frame_id + "': " + e.what());
      return;
    }
  }
  const nav_msgs::Odometry odom =
      makeOdometry(pipeline_->odometry(), pair.header.stamp, params_.odom_frame, child, base_from_camera);
  if (odom_pub_.getNumSubscribers() > 0) odom_pub_.publish(odom);
  if (params_.publish_odom_tf) {
    geometry_msgs::TransformStamped t;
    t.header = odom.header;
    t.child_frame_id = odom.child_frame_id;
    t.transform.translation.x = odom.pose.pose.position.x;
    t.transform.translation.y = odom.pose.pose.position.y;
    t.transform.translation.z = odom.pose.pose.position.z;
    t.transform.rotation = odom.pose.pose.orientation;
    tf_broadcaster_->sendTransform(t);
  }
}

void MCFlowNodelet::publishTf(const mc_flow::Result& result, const PairContext& pair) {
  tf_broadcaster_->sendTransform(makeSegmentTransforms(result, pipeline_->tracks(), pair, params_.segment_frame_prefix));
}

void MCFlowNodelet::saveAndSummarise(const mc_flow::Result& result, const PairContext& pair, const cv::Mat& segmentation) {
  if (params_.print_summary) {
    const double dt = pair.interval();
    std::ostringstream s;
    s.setf(std::ios::fixed);
    s.precision(3);
    s << "pair " << pair_index_ << " [" << stampText(pair.header.stamp) << ", dt " << dt << " s]: "
      << result.segments.size() << " segments";
    for (std::size_t i = 0; i < result.segments.size(); ++i) {
      const mc_flow::Segment& seg = result.segments[i];
      const double speed = centroidVelocity(seg, dt).norm();
      const double turn = seg.twist.tail<3>().norm() / dt * 180.0 / M_PI;
      s << " | id " << seg.id << ": " << speed << " m/s " << std::setprecision(1)
        << turn << " deg/s, " << std::setprecision(0) << seg.support << " px" << std::setprecision(3);
    }
    long dropped = 0;
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      dropped = frames_dropped_;
    }
    s << " | solve " << std::setprecision(0) << pair.solve_time_ms << " ms (" << result.backend << "), dropped "
      << dropped;
    NODELET_INFO_STREAM(s.str());
    std::fflush(stdout);  // one line per pair also when stdout is a file (roslaunch logs)
  }
  if (!params_.save_dir.empty()) {
    char name[64];
    cv::Mat bgr;
    cv::cvtColor(segmentation, bgr, cv::COLOR_RGB2BGR);
    std::snprintf(name, sizeof(name), "/segmentation_%06ld.png", pair_index_);
    cv::imwrite(params_.save_dir + name, bgr);
    cv::Mat occlusion(result.occlusion.height, result.occlusion.width, CV_8UC1,
                      const_cast<std::uint8_t*>(result.occlusion.ptr()));
    std::snprintf(name, sizeof(name), "/occlusion_%06ld.png", pair_index_);
    cv::imwrite(params_.save_dir + name, occlusion);
    cv::cvtColor(pair.previous->colour, bgr, cv::COLOR_RGB2BGR);  // the pixels the labels belong to
    std::snprintf(name, sizeof(name), "/colour_%06ld.png", pair_index_);
    cv::imwrite(params_.save_dir + name, bgr);
  }
}

void MCFlowNodelet::warnThrottled(const std::string& key, const std::string& text, double period) {
  const ros::WallTime now = ros::WallTime::now();
  long held_back = 0;
  bool emit = false;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    last_problem_ = text;
    ++warnings_per_kind_[key.substr(0, key.find(':'))];
    WarningState& state = warnings_[key];
    if (state.last_shown.isZero() || (now - state.last_shown).toSec() >= period) {
      held_back = state.held_back;
      state.last_shown = now;
      state.held_back = 0;
      emit = true;
    } else {
      ++state.held_back;
    }
  }
  if (!emit) return;
  if (held_back > 0) {
    NODELET_WARN("%s (%ld more like this since the last such warning)", text.c_str(), held_back);
  } else {
    NODELET_WARN("%s", text.c_str());
  }
}

void MCFlowNodelet::timerCb(const ros::WallTimerEvent&) {
  bool subscribed = false;
  {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    subscribed = subscribed_;
  }
  if (subscribed) {
    // The words come from describeInputSilence (input_watch.h, tested without a node); here we only
    // take the snapshot. Arrival times are this timer's: a count that changed since the last tick.
    InputSnapshot snapshot;
    long counts[3] = {0, 0, 0};
    bool new_since_sync = true;
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      const ros::WallTime now = ros::WallTime::now();
      snapshot.seconds_without_sync = (now - std::max(last_sync_time_, subscribed_since_)).toSec();
      counts[0] = rgb_count_;
      counts[1] = depth_count_;
      counts[2] = info_count_;
      const std::string* names[3] = {&rgb_topic_, &depth_topic_, &info_topic_};
      const char* labels[3] = {"rgb", "depth", "camera_info"};
      for (int i = 0; i < 3; ++i) {
        if (counts[i] != watch_counts_[i] || watch_last_arrival_[i] < subscribed_since_) {
          watch_last_arrival_[i] = counts[i] != watch_counts_[i] ? now : subscribed_since_;
          watch_counts_[i] = counts[i];
        }
        WatchedTopic& t = snapshot.topics[i];
        t.label = labels[i];
        t.topic = *names[i];
        t.received = counts[i];
        t.seconds_since_last = (now - watch_last_arrival_[i]).toSec();
        t.has_stamp = !last_input_stamp_[i].isZero();
        t.stamp = last_input_stamp_[i].toSec();
        new_since_sync = new_since_sync && counts[i] > sync_counts_[i];
      }
    }
    snapshot.approximate_sync = params_.approximate_sync;
    snapshot.approximate_sync_max_interval = params_.approximate_sync_max_interval;
    const std::optional<InputWarning> warning = describeInputSilence(snapshot, params_.no_input_warning_after);
    if (warning && warning->restart_synchroniser) {
      if (new_since_sync) {
        // A synchroniser confused by an irregular stream (dropped or skewed messages) can stay stuck:
        // start it afresh, at most once per new message on every topic.
        warnThrottled(warning->key, warning->text);
        {
          std::lock_guard<std::mutex> lock(stats_mutex_);
          for (int i = 0; i < 3; ++i) sync_counts_[i] = counts[i];
        }
        createSynchroniser();
        std::lock_guard<std::mutex> lock(stats_mutex_);
        ++synchroniser_restarts_;
      }
    } else if (warning) {
      warnThrottled(warning->key, warning->text, std::max(params_.no_input_warning_after, 15.0));
    }
  }
  updater_->update();
}

void MCFlowNodelet::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  const ros::WallTime now = ros::WallTime::now();
  while (!sync_times_.empty() && (now - sync_times_.front()).toSec() > 10.0) sync_times_.pop_front();
  double rate = 0;
  if (sync_times_.size() >= 2) {
    rate = double(sync_times_.size() - 1) / std::max((sync_times_.back() - sync_times_.front()).toSec(), 1e-6);
  }
  const bool silent = subscribed_ && (now - std::max(last_sync_time_, subscribed_since_)).toSec() > params_.no_input_warning_after;
  if (!subscribed_) {
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "idle: no listener on any output");
  } else if (silent) {
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no synchronised input");
  } else if (on_cpu_after_failure_) {
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "running on the CPU after a GPU failure");
  } else {
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "running");
  }
  status.add("input rate [Hz]", rate);
  status.add("frames synchronised", frames_synced_);
  status.add("pairs solved", pairs_solved_);
  status.add("frames dropped (arrived while solving)", frames_dropped_);
  status.add("frames skipped (bad input)", frames_skipped_);
  status.add("sequence resets", sequence_resets_);
  status.add("pairs started warm", warm_starts_);
  status.add("pairs started cold after a refused warm start", cold_fallbacks_);
  status.add("last start", last_start_.empty() ? std::string("(no pair solved yet)") : last_start_);
  status.add("received rgb / depth / camera_info", std::to_string(rgb_count_) + " / " + std::to_string(depth_count_) +
                                                      " / " + std::to_string(info_count_));
  status.add("lost before the callbacks rgb / depth / camera_info (header.seq gaps)",
             std::to_string(lost_before_callback_[0]) + " / " + std::to_string(lost_before_callback_[1]) + " / " +
                 std::to_string(lost_before_callback_[2]));
  status.add("held back (repeated or backward stamps) rgb / depth / camera_info",
             std::to_string(held_back_[0]) + " / " + std::to_string(held_back_[1]) + " / " + std::to_string(held_back_[2]));
  status.add("synchroniser restarts", synchroniser_restarts_);
  for (const auto& [kind, count] : warnings_per_kind_) status.add("warnings: " + kind, count);
  status.add("solve time mean [ms]", pairs_solved_ > 0 ? total_solve_ms_ / double(pairs_solved_) : 0.0);
  status.add("solve time last [ms]", last_timings_.total);
  status.add("stage preprocessing [ms]", last_timings_.preprocessing);
  status.add("stage initialisation [ms]", last_timings_.initialisation);
  status.add("stage motion [ms]", last_timings_.motion);
  status.add("stage labels [ms]", last_timings_.labels);
  status.add("stage adaptation [ms]", last_timings_.adaptation);
  status.add("stage occlusion [ms]", last_timings_.occlusion);
  status.add("stage outputs [ms]", last_timings_.outputs);
  status.add("backend", backend_.empty() ? std::string("(no pair solved yet)") : backend_ + ": " + backend_note_);
  status.add("backend fallbacks (GPU failures)", backend_fallbacks_);
  status.add("last backend failure", last_backend_failure_.empty() ? std::string("none") : last_backend_failure_);
  status.add("last problem", last_problem_.empty() ? std::string("none") : last_problem_);
}

std::vector<std::pair<std::string, std::string>> NodeParameters::defaults() {
  const NodeParameters d;
  auto text = [](double v) {
    std::ostringstream s;
    s << v;
    return s.str();
  };
  auto flag = [](bool v) { return std::string(v ? "true" : "false"); };
  return {{"queue_size", std::to_string(d.queue_size)},
          {"max_input_pixels", std::to_string(d.max_input_pixels)},
          {"approximate_sync", flag(d.approximate_sync)},
          {"approximate_sync_max_interval", text(d.approximate_sync_max_interval)},
          {"downsample", std::to_string(d.downsample)},
          {"max_stamp_difference", text(d.max_stamp_difference)},
          {"max_pair_interval", text(d.max_pair_interval)},
          {"no_input_warning_after", text(d.no_input_warning_after)},
          {"publish_tf", flag(d.publish_tf)},
          {"segment_frame_prefix", d.segment_frame_prefix},
          {"odom_frame", d.odom_frame},
          {"base_frame", d.base_frame},
          {"publish_odom_tf", flag(d.publish_odom_tf)},
          {"prior_frame", d.prior_frame},
          {"cloud_colour", d.cloud_colour},
          {"marker_seconds_ahead", text(d.marker_seconds_ahead)},
          {"segmentation_blend", text(d.segmentation_blend)},
          {"print_summary", flag(d.print_summary)},
          {"save_dir", d.save_dir}};
}

}  // namespace mc_flow_ros

PLUGINLIB_EXPORT_CLASS(mc_flow_ros::MCFlowNodelet, nodelet::Nodelet)
