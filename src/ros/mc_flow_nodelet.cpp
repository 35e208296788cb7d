#include "mc_flow/ros/mc_flow_nodelet.h"

#include <algorithm>
#include <utility>

#include <pluginlib/class_list_macros.hpp>
#include <tf2_eigen/tf2_eigen.h>

#include "mc_flow/core/error.h"
#include "mc_flow/ros/node_parameter_reading.h"
#include "mc_flow/ros/reconfigure.h"
#include "mc_flow/ros/startup_report.h"

namespace mc_flow_ros {

MCFlowNodelet::~MCFlowNodelet() {
  timer_.stop();
  {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    if (inputs_) inputs_->unsubscribe();
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
  params_ = readNodeParameters(pnh_);
  for (const std::string& problem : params_.sanitise()) NODELET_WARN("%s", problem.c_str());
  if (const std::optional<std::string> problem = makeSaveDir(params_.save_dir)) {
    NODELET_ERROR("%s", problem->c_str());
    params_.save_dir.clear();
  }

  inputs_ = std::make_unique<InputSubscription>(nh_, pnh_);
  it_out_ = std::make_unique<image_transport::ImageTransport>(pnh_);
  gate_ = std::make_unique<InputGate>(inputs_->topics());
  createSynchroniser();
  // Every message passes the gate on its way to the synchroniser.
  inputs_->rgb().registerCallback(
      boost::function<void(const sensor_msgs::ImageConstPtr&)>([this](const sensor_msgs::ImageConstPtr& m) {
        if (admit(InputGate::kRgb, m->header)) rgb_pass_.add(m);
      }));
  inputs_->depth().registerCallback(
      boost::function<void(const sensor_msgs::ImageConstPtr&)>([this](const sensor_msgs::ImageConstPtr& m) {
        if (admit(InputGate::kDepth, m->header)) depth_pass_.add(m);
      }));
  inputs_->info().registerCallback(
      boost::function<void(const sensor_msgs::CameraInfoConstPtr&)>([this](const sensor_msgs::CameraInfoConstPtr& m) {
        if (admit(InputGate::kCameraInfo, m->header)) info_pass_.add(m);
      }));

  // The solver config comes from dynamic_reconfigure (initial values: private parameters or the core's defaults, see
  // cfg/McFlow.cfg); the first callback happens inside the server's constructor path.
  reconfigure_server_ = std::make_unique<dynamic_reconfigure::Server<mc_flow::McFlowConfig>>(reconfigure_mutex_, pnh_);
  reconfigure_server_->setCallback(
      boost::bind(&MCFlowNodelet::reconfigureCb, this, boost::placeholders::_1, boost::placeholders::_2));

  updater_ = std::make_unique<diagnostic_updater::Updater>(nh_, pnh_, getName());
  updater_->setHardwareID("mc_flow:" + gate_->topic(InputGate::kRgb));
  updater_->add("MC-Flow", [this](diagnostic_updater::DiagnosticStatusWrapper& status) {
    status_.fill(status, *gate_, subscribed_, ros::WallTime::now(), params_.no_input_warning_after);
  });

  if (!params_.base_frame.empty() || !params_.prior_frame.empty()) {
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_);
  }
  worker_ = std::thread(&MCFlowNodelet::workerLoop, this);
  {
    // Hold the lock while advertising: a connect callback must not subscribe before everything exists.
    std::lock_guard<std::mutex> lock(connect_mutex_);
    outputs_ = std::make_unique<OutputPublishers>(
        pnh_, *it_out_, params_, [this] { connectCb(); }, tf_buffer_.get(), getName());
  }
  mc_flow::Config solver;
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    if (pending_config_) solver = *pending_config_;
  }
  NODELET_INFO_STREAM(startupText(getName(), params_, inputs_->topics(), outputs_->topics(), solver));
  connectCb();  // demo options (print_summary, save_dir, publish_tf) need results without listeners
  timer_ = nh_.createWallTimer(ros::WallDuration(1.0), &MCFlowNodelet::timerCb, this);
}

void MCFlowNodelet::createSynchroniser() {
  approximate_sync_.reset();
  exact_sync_.reset();
  const auto callback = boost::bind(&MCFlowNodelet::syncCb, this, boost::placeholders::_1, boost::placeholders::_2,
                                    boost::placeholders::_3);
  if (params_.approximate_sync) {
    ApproximatePolicy policy(params_.queue_size);
    policy.setReset(true);  // a bag restarting under /clock clears the queues instead of stalling them
    approximate_sync_ = std::make_unique<message_filters::Synchronizer<ApproximatePolicy>>(
        std::as_const(policy), rgb_pass_, depth_pass_, info_pass_);
    if (params_.approximate_sync_max_interval > 0) {
      approximate_sync_->setMaxIntervalDuration(ros::Duration(params_.approximate_sync_max_interval));
    }
    approximate_sync_->registerCallback(callback);
  } else {
    ExactPolicy policy(params_.queue_size);
    policy.setReset(true);
    exact_sync_ = std::make_unique<message_filters::Synchronizer<ExactPolicy>>(std::as_const(policy), rgb_pass_,
                                                                               depth_pass_, info_pass_);
    exact_sync_->registerCallback(callback);
  }
}

bool MCFlowNodelet::admit(int topic, const std_msgs::Header& header) {
  const InputGate::Admission admission = gate_->admit(topic, header, ros::WallTime::now());
  if (!admission.warning.empty()) warn(admission.warning_key, admission.warning);
  // All callbacks of this nodelet are serialised, so rebuilding the synchroniser here is safe.
  if (admission.restart_synchroniser) createSynchroniser();
  return admission.pass;
}

void MCFlowNodelet::connectCb() {
  std::lock_guard<std::mutex> lock(connect_mutex_);
  const bool needed = outputs_->anyListener() || params_.print_summary || !params_.save_dir.empty() ||
                      params_.publish_tf || params_.publish_odom_tf;
  if (needed && !subscribed_) {
    // One queue length for the subscribers and the synchroniser: a burst the synchroniser could hold must not be
    // dropped before it (the losses that remain show in diagnostics). A transport whose plug-in is missing or cannot
    // subscribe is an error here, and raw is used instead.
    for (const std::string& error : inputs_->subscribe(std::uint32_t(params_.queue_size)))
      NODELET_ERROR("%s", error.c_str());
    subscribed_ = true;
    gate_->subscribed(ros::WallTime::now());
    NODELET_DEBUG("an output has a listener: subscribed to the inputs");
  } else if (!needed && subscribed_) {
    inputs_->unsubscribe();
    subscribed_ = false;
    NODELET_DEBUG("no output has a listener: unsubscribed from the inputs");
    // The next frame after a pause must not be paired with one from before it: the worker starts a new sequence
    // (it owns the pipeline, so it is told through a flag).
    std::lock_guard<std::mutex> pending(pending_mutex_);
    pending_.reset();
    sequence_break_ = true;
  }
}

void MCFlowNodelet::syncCb(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::ImageConstPtr& depth,
                           const sensor_msgs::CameraInfoConstPtr& info) {
  gate_->synchronised(ros::WallTime::now());
  if (const std::optional<std::string> skew =
          stampDifferenceWarning(rgb->header.stamp, depth->header.stamp, params_.max_stamp_difference))
    warn("stamps", *skew);
  bool dropped = false;
  {
    std::lock_guard<std::mutex> lock(pending_mutex_);
    dropped = pending_.has_value();  // the worker is still busy: the waiting frame is replaced by this one
    pending_ = SyncedInput{rgb, depth, info};
  }
  if (dropped) status_.frameDropped();
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
            pipeline_ =
                std::make_unique<mc_flow::SequencePipeline>(config, 1, params_.max_pair_interval, make_backend_);
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
      warn("unexpected", std::string("frame skipped after an unexpected error: ") + e.what());
      status_.frameSkipped();
    }
  }
}

void MCFlowNodelet::process(const SyncedInput& input) {
  if (!pipeline_) return;
  FrameInput current;
  try {
    current = toFrameInput(*input.rgb, *input.depth, *input.info, params_.downsample,
                           std::uint64_t(params_.max_input_pixels), solver_config_.depth_downsample_range);
  } catch (const FrameInputError& e) {
    warn(inputWarningKey(e), std::string("frame ") + stampText(input.rgb->header.stamp) + " skipped: " + e.what());
    status_.frameSkipped();
    return;
  }

  // The frame is already at the processing resolution (toFrameInput applies the core's downsampling rule): the
  // pipeline pairs, solves and tracks. The display data travel with the frame.
  const ros::Time stamp = current.header.stamp;
  std::optional<Eigen::Matrix4d> prior = cameraPosePrior(current.header);
  mc_flow::StreamFrame frame = toStreamFrame(std::move(current));
  frame.camera_pose_prior = std::move(prior);
  const ros::WallTime start = ros::WallTime::now();
  mc_flow::SequenceStep step;
  try {
    pipeline_->setOutputs(outputs_->wantedOutputs());
    step = pipeline_->push(std::move(frame));
  } catch (const mc_flow::InputError& e) {
    warn("input", "frame " + stampText(stamp) + " skipped: " + e.what());
    status_.frameSkipped();
    return;
  }
  const double solve_ms = (ros::WallTime::now() - start).toSec() * 1e3;
  for (const StepWarning& w : status_.recordStep(step, stampText(stamp), solve_ms)) warn(w.key, w.text, w.period);
  if (step.outcome != mc_flow::SequenceStep::Outcome::Solved) return;

  const mc_flow::Result& result = *step.result;
  reportBackend(result);
  outputs_->publish(result, pairContext(step, solve_ms), *pipeline_, step.pair_index, status_.framesDropped(),
                    [this](const std::string& key, const std::string& text) { warn(key, text); });
}

std::optional<Eigen::Matrix4d> MCFlowNodelet::cameraPosePrior(const std_msgs::Header& header) {
  if (params_.prior_frame.empty()) return std::nullopt;
  try {
    // A short wait: the other source's TF usually arrives within a few milliseconds of the images.
    return tf2::transformToEigen(
               tf_buffer_->lookupTransform(params_.prior_frame, header.frame_id, header.stamp, ros::Duration(0.02)))
        .matrix();
  } catch (const tf2::TransformException& e) {
    warn("prior", "no static-world prior for frame " + stampText(header.stamp) + ": no transform from prior_frame '" +
                      params_.prior_frame + "' to '" + header.frame_id + "': " + e.what());
    return std::nullopt;
  }
}

void MCFlowNodelet::reportBackend(const mc_flow::Result& result) {
  if (backend_reported_) return;
  backend_reported_ = true;
  const BackendReport report = backendReport(result, solver_config_);
  if (report.warning)
    NODELET_WARN("%s", report.text.c_str());
  else
    NODELET_INFO("%s", report.text.c_str());
  if (!report.debug.empty()) NODELET_DEBUG("%s", report.debug.c_str());
}

void MCFlowNodelet::warn(const std::string& key, const std::string& text, double period) {
  if (const std::optional<std::string> shown = status_.warning(key, text, ros::WallTime::now(), period))
    NODELET_WARN("%s", shown->c_str());
}

void MCFlowNodelet::timerCb(const ros::WallTimerEvent&) {
  if (subscribed_) {
    const InputGate::Watch watch = gate_->watch(ros::WallTime::now(), params_.approximate_sync,
                                                params_.approximate_sync_max_interval, params_.no_input_warning_after);
    if (watch.restart_synchroniser) {
      warn(watch.warning->key, watch.warning->text);
      createSynchroniser();
    } else if (watch.warning) {
      warn(watch.warning->key, watch.warning->text, std::max(params_.no_input_warning_after, 15.0));
    }
  }
  updater_->update();
}

}  // namespace mc_flow_ros

PLUGINLIB_EXPORT_CLASS(mc_flow_ros::MCFlowNodelet, nodelet::Nodelet)
