/**
 * @file rostest_common.h
 * @brief Helpers of the node-level tests: a synthetic RGB-D camera publishing into the nodelet, output
 * collectors and a /rosout watcher.
 */
#pragma once

#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include "mc_flow/SegmentArray.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace mcflow_test {

/// @brief Renders the synthetic sequence and turns frames into camera messages.
class SyntheticCamera {
 public:
  SyntheticCamera(ros::NodeHandle& nh, int width, int height, int variant = 0);

  /// @brief Frame t as messages (rgb8 colour, 32FC1 depth, camera_info), all stamped `stamp`.
  sensor_msgs::ImagePtr rgb(int t, const ros::Time& stamp);
  sensor_msgs::ImagePtr depth(int t, const ros::Time& stamp, const std::string& encoding = "32FC1");
  sensor_msgs::CameraInfoPtr info(const ros::Time& stamp);
  /// @brief Publishes frame t with one stamp on all three topics.
  void publish(int t, const ros::Time& stamp);
  void publish(const sensor_msgs::ImagePtr& rgb, const sensor_msgs::ImagePtr& depth,
               const sensor_msgs::CameraInfoPtr& info);
  /// @brief Subscribers of the three input topics (the nodelet's, when it has subscribed).
  int inputSubscribers() const;
  const mc_flow::SyntheticSceneOptions& options() const { return options_; }
  const mc_flow::Intrinsics& intrinsics() { return K_; }

  static const char* frameId() { return "synthetic_rgb_optical_frame"; }

 private:
  void render(int t);
  mc_flow::SyntheticSceneOptions options_;
  mc_flow::Intrinsics K_;
  std::map<int, std::pair<mc_flow::RgbdFrame, mc_flow::ImageU8>> frames_;
  ros::Publisher rgb_pub_, depth_pub_, info_pub_;
};

/// @brief Keeps every message received on one topic.
template <class M>
class Collector {
 public:
  Collector(ros::NodeHandle& nh, const std::string& topic) {
    sub_ = nh.subscribe<M>(topic, 50, [this](const boost::shared_ptr<const M>& m) {
      std::lock_guard<std::mutex> lock(mutex_);
      messages_.push_back(m);
    });
  }
  std::vector<boost::shared_ptr<const M>> messages() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return messages_;
  }
  std::size_t count() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return messages_.size();
  }
  void shutdown() { sub_.shutdown(); }

 private:
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::vector<boost::shared_ptr<const M>> messages_;
};

/// @brief Records WARN and above from /rosout.
class RosoutWatcher {
 public:
  explicit RosoutWatcher(ros::NodeHandle& nh);
  /// @brief True when a WARN/ERROR containing `text` has been seen.
  bool seen(const std::string& text) const;
  std::vector<std::string> all() const;
  /// @brief How many WARN/ERROR lines contain `text` (a throttled warning's shown lines).
  int count(const std::string& text) const;
  /// @brief Every line seen, each on a line of its own: for a failure's message.
  std::string dump() const;
  /// @brief Nodes whose /rosout this watcher is connected to (a warning logged before the connection is not seen).
  int publishers() const { return int(sub_.getNumPublishers()); }

 private:
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::vector<std::string> messages_;
};

/// @brief The ~segments message of the pair ending at `stamp` among those collected, or null.
mc_flow::SegmentArray::ConstPtr pairEndingAt(const Collector<mc_flow::SegmentArray>& segments, const ros::Time& stamp);
/// @brief Frames in lockstep: publishes frame `t` at `stamp` and waits (up to 60 s) for the pair ending at it; null
/// when none came.
mc_flow::SegmentArray::ConstPtr solvePair(SyntheticCamera& camera, const Collector<mc_flow::SegmentArray>& segments,
                                          int t, const ros::Time& stamp);
/// @brief Publishes a frame that starts a sequence (no pair, no output) and gives the nodelet's worker 0.5 s to take
/// it.
void startSequence(SyntheticCamera& camera, int t, const ros::Time& stamp);
/// @brief The id of the segment with the most support (the background in the synthetic scene); 0 when none.
std::uint32_t largestId(const mc_flow::SegmentArray& pair);

/// @brief Value of `key` in the last MC-Flow diagnostic status seen (empty when none).
std::string diagnosticValue(const Collector<diagnostic_msgs::DiagnosticArray>& diagnostics, const std::string& key);
/// @brief diagnosticValue as a number; -1 when the key was not seen.
long diagnosticCount(const Collector<diagnostic_msgs::DiagnosticArray>& diagnostics, const std::string& key);

/// @brief Waits (wall time, spinning in the background) until `done` or `timeout_s`; returns done().
bool waitFor(const std::function<bool()>& done, double timeout_s);

}  // namespace mcflow_test
