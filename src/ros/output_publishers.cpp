#include "mc_flow/ros/output_publishers.h"

#include <cmath>
#include <cstdio>
#include <iomanip>
#include <sstream>

#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <ros/console.h>
#include <tf2_eigen/tf2_eigen.h>
#include <visualization_msgs/MarkerArray.h>

#include "mc_flow/SegmentArray.h"
#include "mc_flow/ros/input_gate.h"

namespace mc_flow_ros {

OutputPublishers::OutputPublishers(ros::NodeHandle& nh, image_transport::ImageTransport& it,
                                   const NodeParameters& params, const std::function<void()>& connect,
                                   tf2_ros::Buffer* tf_buffer, std::string logger)
    : params_(params),
      logger_(std::move(logger)),
      cloud_colour_(params.cloud_colour == "image" ? CloudColour::Image : CloudColour::Segment),
      tf_buffer_(tf_buffer) {
  if (params.publish_tf || params.publish_odom_tf) tf_broadcaster_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  auto image_connect = [connect](const image_transport::SingleSubscriberPublisher&) { connect(); };
  auto message_connect = [connect](const ros::SingleSubscriberPublisher&) { connect(); };
  soft_labels_ = it.advertise("soft_labels", 1, image_connect, image_connect);
  labels_ = it.advertise("labels", 1, image_connect, image_connect);
  segmentation_ = it.advertise("segmentation", 1, image_connect, image_connect);
  occlusion_ = it.advertise("occlusion", 1, image_connect, image_connect);
  moving_mask_ = it.advertise("moving_mask", 1, image_connect, image_connect);
  segments_ = nh.advertise<mc_flow::SegmentArray>("segments", 5, message_connect, message_connect);
  cloud_ = nh.advertise<sensor_msgs::PointCloud2>("scene_flow", 1, message_connect, message_connect);
  markers_ = nh.advertise<visualization_msgs::MarkerArray>("motion_markers", 1, message_connect, message_connect);
  info_ = nh.advertise<sensor_msgs::CameraInfo>("camera_info", 1, message_connect, message_connect);
  odom_ = nh.advertise<nav_msgs::Odometry>("odom", 5, message_connect, message_connect);
  camera_path_ = nh.advertise<nav_msgs::Path>("camera_path", 1, message_connect, message_connect);
}

bool OutputPublishers::anyListener() const {
  for (const image_transport::Publisher* p : {&soft_labels_, &labels_, &segmentation_, &occlusion_, &moving_mask_})
    if (p->getNumSubscribers() > 0) return true;
  for (const ros::Publisher* p : {&segments_, &cloud_, &markers_, &info_, &odom_, &camera_path_})
    if (p->getNumSubscribers() > 0) return true;
  return false;
}

mc_flow::OutputSelection OutputPublishers::wantedOutputs() const {
  mc_flow::OutputSelection wanted;
  wanted.soft_labels =
      soft_labels_.getNumSubscribers() > 0 || segmentation_.getNumSubscribers() > 0 || !params_.save_dir.empty();
  wanted.scene_flow = cloud_.getNumSubscribers() > 0;
  return wanted;
}

std::string OutputPublishers::topics() const {
  std::string out;
  for (const ros::Publisher* p : {&segments_, &cloud_, &markers_, &info_, &odom_, &camera_path_})
    out += p->getTopic() + ", ";
  for (const image_transport::Publisher* p : {&soft_labels_, &labels_, &segmentation_, &occlusion_, &moving_mask_})
    out += p->getTopic() + ", ";
  out.resize(out.size() - 2);
  if (params_.publish_tf || params_.publish_odom_tf) out += ", /tf";
  return out;
}

void OutputPublishers::publish(const mc_flow::Result& result, const PairContext& pair,
                               const mc_flow::SequencePipeline& pipeline, long pair_index, long frames_dropped,
                               const Warn& warn) {
  if (segments_.getNumSubscribers() > 0) segments_.publish(makeSegmentArray(result, pair));
  // A subscriber that arrived during the solve gets the soft labels and the scene flow from the next pair on (the solve
  // left out what nobody had asked for: wantedOutputs).
  const bool have_soft_labels = result.soft_labels.count > 0, have_scene_flow = !result.scene_flow.empty();
  // The three large messages are filled together (one wake of the OpenMP threads), then published in turn.
  ImageOutputRequest request;
  request.soft_labels = soft_labels_.getNumSubscribers() > 0 && have_soft_labels;
  request.segmentation = segmentation_.getNumSubscribers() > 0 && have_soft_labels;
  request.scene_flow = cloud_.getNumSubscribers() > 0 && have_scene_flow;
  request.segmentation_blend = params_.segmentation_blend;
  request.cloud_colour = cloud_colour_;
  request.soft_labels_pool = &soft_labels_pool_;
  request.segmentation_pool = &segmentation_pool_;
  request.cloud_pool = &cloud_pool_;
  const ImageOutputs built = makeImageOutputs(result, pair, request);
  if (built.soft_labels) soft_labels_.publish(built.soft_labels);
  if (labels_.getNumSubscribers() > 0) labels_.publish(makeLabelsImage(result, pair, &labels_pool_));
  if (occlusion_.getNumSubscribers() > 0) occlusion_.publish(makeOcclusionImage(result, pair, &occlusion_pool_));
  // The picture is rendered into the message; save_dir reads it there (or, without a subscriber, from a picture of its
  // own). `built` holds the message to the end.
  cv::Mat segmentation;
  if (built.segmentation) {
    segmentation_.publish(built.segmentation);
    segmentation = cv::Mat(int(built.segmentation->height), int(built.segmentation->width), CV_8UC3,
                           built.segmentation->data.data(), built.segmentation->step);
  } else if (!params_.save_dir.empty() && have_soft_labels) {
    segmentation = segmentationPicture(result, pair, params_.segmentation_blend);
  }
  if (built.scene_flow) cloud_.publish(built.scene_flow);
  if (markers_.getNumSubscribers() > 0) markers_.publish(makeMotionMarkers(result, pair, params_.marker_seconds_ahead));
  if (info_.getNumSubscribers() > 0) info_.publish(processingCameraInfo(*pair.current));
  if (moving_mask_.getNumSubscribers() > 0 && pair.world) {
    moving_mask_.publish(makeMovingMaskImage(result, *pair.world, pair, &moving_mask_pool_));
  }
  if (params_.publish_tf) {
    tf_broadcaster_->sendTransform(
        makeSegmentTransforms(result, pipeline.tracks(), pair, params_.segment_frame_prefix));
  }
  if (odom_.getNumSubscribers() > 0 || params_.publish_odom_tf) publishOdometry(pair, pipeline.odometry(), warn);
  camera_poses_.push_back(pipeline.odometry().pose);
  if (camera_poses_.size() > kCameraPathPoses) camera_poses_.pop_front();
  if (camera_path_.getNumSubscribers() > 0) camera_path_.publish(makeCameraPath(camera_poses_, pair.header));
  if (params_.print_summary || !params_.save_dir.empty()) {
    saveAndSummarise(result, pair, segmentation, pair_index, frames_dropped);
  }
}

void OutputPublishers::publishOdometry(const PairContext& pair, const mc_flow::Odometry& odometry, const Warn& warn) {
  // The camera's mount on the base (REP 105: odometry of base_frame); without base_frame, the camera's optical frame.
  Eigen::Isometry3d base_from_camera = Eigen::Isometry3d::Identity();
  std::string child = pair.header.frame_id;
  if (!params_.base_frame.empty()) {
    try {
      base_from_camera = tf2::transformToEigen(tf_buffer_->lookupTransform(params_.base_frame, pair.header.frame_id,
                                                                           pair.header.stamp, ros::Duration(0.05)));
      child = params_.base_frame;
    } catch (const tf2::TransformException& e) {
      warn("odom_mount", "~odom not published: no transform from base_frame '" + params_.base_frame +
                             "' to the camera frame '" + pair.header.frame_id + "': " + e.what());
      return;
    }
  }
  const nav_msgs::Odometry odom =
      makeOdometry(odometry, pair.header.stamp, params_.odom_frame, child, base_from_camera);
  if (odom_.getNumSubscribers() > 0) odom_.publish(odom);
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

void OutputPublishers::saveAndSummarise(const mc_flow::Result& result, const PairContext& pair,
                                        const cv::Mat& segmentation, long pair_index, long frames_dropped) const {
  if (params_.print_summary) {
    const double dt = pair.interval();
    std::ostringstream s;
    s.setf(std::ios::fixed);
    s.precision(3);
    s << "pair " << pair_index << " [" << stampText(pair.header.stamp) << ", dt " << dt
      << " s]: " << result.segments.size() << " segments";
    for (const mc_flow::Segment& seg : result.segments) {
      const double speed = centroidVelocity(seg, dt).norm();
      const double turn = seg.twist.tail<3>().norm() / dt * 180.0 / M_PI;
      s << " | id " << seg.id << ": " << speed << " m/s " << std::setprecision(1) << turn << " deg/s, "
        << std::setprecision(0) << seg.support << " px" << std::setprecision(3);
    }
    s << " | solve " << std::setprecision(0) << pair.solve_time_ms << " ms (" << result.backend << "), dropped "
      << frames_dropped;
    ROS_INFO_STREAM_NAMED(logger_, s.str());
    std::fflush(stdout);  // one line per pair also when stdout is a file (roslaunch logs)
  }
  if (!params_.save_dir.empty()) {
    char name[64];
    cv::Mat bgr;
    if (!segmentation.empty()) {  // empty when the solve left out the soft labels (save_dir set during it)
      cv::cvtColor(segmentation, bgr, cv::COLOR_RGB2BGR);
      std::snprintf(name, sizeof(name), "/segmentation_%06ld.png", pair_index);
      cv::imwrite(params_.save_dir + name, bgr);
    }
    cv::Mat occlusion(result.occlusion.height, result.occlusion.width, CV_8UC1,
                      const_cast<std::uint8_t*>(result.occlusion.ptr()));
    std::snprintf(name, sizeof(name), "/occlusion_%06ld.png", pair_index);
    cv::imwrite(params_.save_dir + name, occlusion);
    cv::cvtColor(pair.previous->colour, bgr, cv::COLOR_RGB2BGR);  // the pixels the labels belong to
    std::snprintf(name, sizeof(name), "/colour_%06ld.png", pair_index);
    cv::imwrite(params_.save_dir + name, bgr);
  }
}

}  // namespace mc_flow_ros
