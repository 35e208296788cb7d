#include "rostest_common.h"

#include <algorithm>
#include <cstring>

#include <sensor_msgs/image_encodings.h>

namespace mcflow_test {

SyntheticCamera::SyntheticCamera(ros::NodeHandle& nh, int width, int height, int variant) {
  options_.width = width;
  options_.height = height;
  options_.variant = variant;
  rgb_pub_ = nh.advertise<sensor_msgs::Image>("/camera/rgb/image_rect_color", 5);
  depth_pub_ = nh.advertise<sensor_msgs::Image>("/camera/depth_registered/image_rect", 5);
  info_pub_ = nh.advertise<sensor_msgs::CameraInfo>("/camera/rgb/camera_info", 5);
}

void SyntheticCamera::render(int t) {
  if (frames_.count(t)) return;
  auto& entry = frames_[t];
  mc_flow::renderSyntheticFrame(options_, t, entry.first, entry.second, K_);
}

sensor_msgs::ImagePtr SyntheticCamera::rgb(int t, const ros::Time& stamp) {
  render(t);
  const auto& colour = frames_[t].second;
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->header.stamp = stamp;
  msg->header.frame_id = frameId();
  msg->width = std::uint32_t(colour.width);
  msg->height = std::uint32_t(colour.height);
  msg->encoding = sensor_msgs::image_encodings::RGB8;
  msg->step = msg->width * 3;
  msg->data.assign(colour.data.begin(), colour.data.end());
  return msg;
}

sensor_msgs::ImagePtr SyntheticCamera::depth(int t, const ros::Time& stamp, const std::string& encoding) {
  render(t);
  const auto& depth = frames_[t].first.depth;
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->header.stamp = stamp;
  msg->header.frame_id = frameId();
  msg->width = std::uint32_t(depth.width);
  msg->height = std::uint32_t(depth.height);
  msg->encoding = encoding;
  if (encoding == "16UC1") {
    msg->step = msg->width * 2;
    msg->data.resize(msg->step * msg->height);
    for (std::size_t i = 0; i < depth.data.size(); ++i) {
      const float z = depth.data[i];
      const std::uint16_t mm = mc_flow::isValidDepth(z) ? std::uint16_t(z * 1000.f + 0.5f) : 0;
      std::memcpy(&msg->data[2 * i], &mm, 2);
    }
  } else {
    msg->step = msg->width * 4;
    msg->data.resize(msg->step * msg->height);
    for (std::size_t i = 0; i < depth.data.size(); ++i) {
      const float z = mc_flow::isValidDepth(depth.data[i]) ? depth.data[i] : std::nanf("");
      std::memcpy(&msg->data[4 * i], &z, 4);
    }
  }
  return msg;
}

sensor_msgs::CameraInfoPtr SyntheticCamera::info(const ros::Time& stamp) {
  render(0);
  auto msg = boost::make_shared<sensor_msgs::CameraInfo>();
  msg->header.stamp = stamp;
  msg->header.frame_id = frameId();
  msg->width = std::uint32_t(options_.width);
  msg->height = std::uint32_t(options_.height);
  msg->distortion_model = "plumb_bob";
  msg->D.assign(5, 0.0);
  msg->K = {K_.fx, 0, K_.cx, 0, K_.fy, K_.cy, 0, 0, 1};
  msg->R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  msg->P = {K_.fx, 0, K_.cx, 0, 0, K_.fy, K_.cy, 0, 0, 0, 1, 0};
  return msg;
}

void SyntheticCamera::publish(int t, const ros::Time& stamp) { publish(rgb(t, stamp), depth(t, stamp), info(stamp)); }

void SyntheticCamera::publish(const sensor_msgs::ImagePtr& rgb, const sensor_msgs::ImagePtr& depth,
                              const sensor_msgs::CameraInfoPtr& info) {
  info_pub_.publish(info);
  depth_pub_.publish(depth);
  rgb_pub_.publish(rgb);
}

int SyntheticCamera::inputSubscribers() const {
  return int(rgb_pub_.getNumSubscribers() + depth_pub_.getNumSubscribers() + info_pub_.getNumSubscribers());
}

RosoutWatcher::RosoutWatcher(ros::NodeHandle& nh) {
  sub_ = nh.subscribe<rosgraph_msgs::Log>("/rosout", 500, [this](const rosgraph_msgs::LogConstPtr& m) {
    if (m->level < rosgraph_msgs::Log::WARN) return;
    std::lock_guard<std::mutex> lock(mutex_);
    messages_.push_back(m->name + ": " + m->msg);
  });
}

bool RosoutWatcher::seen(const std::string& text) const {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& m : messages_) {
    if (m.find(text) != std::string::npos) return true;
  }
  return false;
}

std::vector<std::string> RosoutWatcher::all() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return messages_;
}

int RosoutWatcher::count(const std::string& text) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return int(std::count_if(messages_.begin(), messages_.end(),
                           [&](const std::string& m) { return m.find(text) != std::string::npos; }));
}

std::string RosoutWatcher::dump() const {
  std::string text;
  for (const auto& m : all()) text += "\n  " + m;
  return text;
}

mc_flow::SegmentArray::ConstPtr pairEndingAt(const Collector<mc_flow::SegmentArray>& segments, const ros::Time& stamp) {
  for (const auto& m : segments.messages())
    if (m->header.stamp == stamp) return m;
  return nullptr;
}

mc_flow::SegmentArray::ConstPtr solvePair(SyntheticCamera& camera, const Collector<mc_flow::SegmentArray>& segments,
                                          int t, const ros::Time& stamp) {
  camera.publish(t, stamp);
  waitFor([&] { return pairEndingAt(segments, stamp) != nullptr; }, 60.0);
  return pairEndingAt(segments, stamp);
}

void startSequence(SyntheticCamera& camera, int t, const ros::Time& stamp) {
  camera.publish(t, stamp);
  ros::WallDuration(0.5).sleep();
}

std::uint32_t largestId(const mc_flow::SegmentArray& pair) {
  const auto it = std::max_element(pair.segments.begin(), pair.segments.end(),
                                   [](const auto& a, const auto& b) { return a.support < b.support; });
  return it == pair.segments.end() ? 0 : it->id;
}

std::string diagnosticValue(const Collector<diagnostic_msgs::DiagnosticArray>& diagnostics, const std::string& key) {
  const auto all = diagnostics.messages();
  for (auto it = all.rbegin(); it != all.rend(); ++it) {
    for (const auto& status : (*it)->status) {
      if (status.name.find("MC-Flow") == std::string::npos) continue;
      for (const auto& kv : status.values) {
        if (kv.key == key) return kv.value;
      }
    }
  }
  return "";
}

long diagnosticCount(const Collector<diagnostic_msgs::DiagnosticArray>& diagnostics, const std::string& key) {
  const std::string v = diagnosticValue(diagnostics, key);
  return v.empty() ? -1 : std::stol(v);
}

bool waitFor(const std::function<bool()>& done, double timeout_s) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout_s);
  while (ros::ok() && ros::WallTime::now() < end) {
    if (done()) return true;
    ros::WallDuration(0.02).sleep();
  }
  return done();
}

}  // namespace mcflow_test
