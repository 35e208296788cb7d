#include "mc_flow/ros/bag_sequence.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <sstream>
#include <vector>

#include <rosbag/bag.h>
#include <rosbag/exceptions.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include "mc_flow/ros/conversions.h"
#include "mc_flow/ros/message_validation.h"

namespace mc_flow_ros {

namespace {

std::string absoluteTopic(const std::string& topic) {
  if (topic.empty()) throw mc_flow::InputError("an empty topic name");
  return topic[0] == '/' ? topic : "/" + topic;
}

std::string secondsText(double seconds) {
  std::ostringstream s;
  s << seconds;
  return s.str();
}

std::string stampText(const ros::Time& t) {
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%u.%09u", t.sec, t.nsec);
  return buffer;
}

/// A message of one topic: where it is in the bag and its header stamp.
struct Entry {
  ros::Time stamp;
  rosbag::MessageInstance message;
};

}  // namespace

struct BagSequence::Impl {
  std::string path;
  BagReadOptions options;
  rosbag::Bag bag;
  sensor_msgs::CameraInfo info;  // the intrinsics every frame is converted with
  std::string info_origin;       // where they come from, for the summary
  struct Frame {
    std::size_t rgb, depth;  // indices into rgb_entries / depth_entries
  };
  std::vector<Entry> rgb_entries, depth_entries;
  std::vector<Frame> frames;

  /// "topic (type, N messages), ..." for every topic of the bag: an error about a topic lists what is there.
  std::string topicList() {
    std::map<std::string, std::pair<std::string, std::size_t>> topics;
    rosbag::View all(bag);
    for (const rosbag::ConnectionInfo* c : all.getConnections()) topics[c->topic].first = c->datatype;
    for (auto& [topic, entry] : topics) entry.second = rosbag::View(bag, rosbag::TopicQuery(topic)).size();
    if (topics.empty()) return "the bag holds no message";
    std::string text = "topics in the bag: ";
    bool first = true;
    for (const auto& [topic, entry] : topics) {
      text += (first ? "" : ", ") + topic + " (" + entry.first + ", " + std::to_string(entry.second) + ")";
      first = false;
    }
    return text;
  }

  /// Throws naming the option and the topic unless the topic has messages, all of type T.
  template <class T>
  void requireTopic(const std::string& topic, const std::string& option) {
    rosbag::View view(bag, rosbag::TopicQuery(topic));
    if (view.size() == 0) {
      throw mc_flow::InputError("bag '" + path + "' has no message on " + option + " '" + topic + "'; " + topicList());
    }
    const std::string wanted = ros::message_traits::datatype<T>();
    for (const rosbag::ConnectionInfo* c : view.getConnections()) {
      if (c->datatype != wanted) {
        throw mc_flow::InputError("bag '" + path + "': " + option + " '" + topic + "' holds " + c->datatype +
                                  " messages, not " + wanted);
      }
      if (c->md5sum != ros::message_traits::md5sum<T>()) {
        throw mc_flow::InputError("bag '" + path + "': " + option + " '" + topic + "' holds " + wanted +
                                  " of another definition (md5sum " + c->md5sum + ", this build reads " +
                                  ros::message_traits::md5sum<T>() + ")");
      }
    }
  }

  std::vector<Entry> readStamps(const std::string& topic) {
    std::vector<Entry> entries;
    rosbag::View view(bag, rosbag::TopicQuery(topic));
    // The header stamp needs the message: each is deserialised here and again when its frame is read, so
    // memory stays at one image whatever the bag's length.
    for (const rosbag::MessageInstance& m : view) {
      const sensor_msgs::Image::ConstPtr image = m.instantiate<sensor_msgs::Image>();
      if (!image)
        throw mc_flow::InputError("bag '" + path + "': a message on '" + topic + "' is not a sensor_msgs/Image");
      entries.push_back({image->header.stamp, m});
    }
    return entries;
  }

  void pair() {
    // Depth messages by stamp, for the nearest-stamp search.
    std::vector<std::size_t> by_stamp(depth_entries.size());
    for (std::size_t j = 0; j < by_stamp.size(); ++j) by_stamp[j] = j;
    std::stable_sort(by_stamp.begin(), by_stamp.end(),
                     [&](std::size_t a, std::size_t b) { return depth_entries[a].stamp < depth_entries[b].stamp; });
    const double tolerance = options.max_stamp_difference;
    std::map<std::size_t, std::pair<double, std::size_t>>
        claim;  // depth -> (|difference|, rgb) of its nearest claimant
    std::vector<std::optional<std::size_t>> chosen(rgb_entries.size());
    for (std::size_t i = 0; i < rgb_entries.size(); ++i) {
      const ros::Time t = rgb_entries[i].stamp;
      auto it = std::lower_bound(by_stamp.begin(), by_stamp.end(), t,
                                 [&](std::size_t j, const ros::Time& s) { return depth_entries[j].stamp < s; });
      std::optional<std::size_t> best;
      double best_difference = 0;
      for (auto candidate : {it, it == by_stamp.begin() ? by_stamp.end() : std::prev(it)}) {
        if (candidate == by_stamp.end()) continue;
        const double difference = std::fabs((depth_entries[*candidate].stamp - t).toSec());
        if (difference <= tolerance && (!best || difference < best_difference)) {
          best = *candidate;
          best_difference = difference;
        }
      }
      if (!best) continue;
      const auto previous = claim.find(*best);
      if (previous != claim.end()) {
        if (previous->second.first <= best_difference) continue;  // the earlier claimant is as near or nearer
        chosen[previous->second.second].reset();
      }
      claim[*best] = {best_difference, i};
      chosen[i] = best;
    }
    for (std::size_t i = 0; i < chosen.size(); ++i)
      if (chosen[i]) frames.push_back({i, *chosen[i]});
  }
};

BagSequence::BagSequence(const std::string& path, const BagReadOptions& options) : impl_(std::make_unique<Impl>()) {
  Impl& d = *impl_;
  d.path = path;
  d.options = options;
  d.options.topics.rgb = absoluteTopic(options.topics.rgb);
  d.options.topics.depth = absoluteTopic(options.topics.depth);
  d.options.topics.info = absoluteTopic(options.topics.info);
  if (!(options.max_stamp_difference >= 0) || !std::isfinite(options.max_stamp_difference))
    throw mc_flow::InputError("max stamp difference " + secondsText(options.max_stamp_difference) + " s: must be >= 0");
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error))
    throw mc_flow::InputError("bag file '" + path +
                              "': " + (std::filesystem::exists(path, error) ? "not a file" : "does not exist"));
  try {
    d.bag.open(path, rosbag::bagmode::Read);
  } catch (const rosbag::BagException& e) {
    throw mc_flow::InputError("bag file '" + path + "' cannot be read: " + e.what());
  }
  const BagTopics& topics = d.options.topics;
  try {
    d.requireTopic<sensor_msgs::Image>(topics.rgb, "--rgb-topic");
    d.requireTopic<sensor_msgs::Image>(topics.depth, "--depth-topic");
    if (options.intrinsics) {
      const mc_flow::Intrinsics& K = *options.intrinsics;
      // width = height = 0: the values are for the images as they are (no rescaling).
      d.info.K = {K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1};
      d.info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
      d.info.P = {K.fx, 0, K.cx, 0, 0, K.fy, K.cy, 0, 0, 0, 1, 0};
      d.info_origin = "intrinsics given";
    } else {
      if (rosbag::View(d.bag, rosbag::TopicQuery(topics.info)).size() == 0) {
        throw mc_flow::InputError("bag '" + path + "' has no message on --info-topic '" + topics.info +
                                  "' (give --info-topic, --intrinsics or --camera-info); " + d.topicList());
      }
      d.requireTopic<sensor_msgs::CameraInfo>(topics.info, "--info-topic");
      rosbag::View view(d.bag, rosbag::TopicQuery(topics.info));
      const sensor_msgs::CameraInfo::ConstPtr first = view.begin()->instantiate<sensor_msgs::CameraInfo>();
      try {
        validateCameraInfo(*first, options.max_pixels);
      } catch (const FrameInputError& e) {
        throw mc_flow::InputError("bag '" + path + "': the first camera_info on '" + topics.info + "' (stamp " +
                                  stampText(first->header.stamp) + ") is unusable: " + e.what());
      }
      d.info = *first;
      d.info_origin =
          "intrinsics from the first camera_info on " + topics.info + " (stamp " + stampText(first->header.stamp) + ")";
    }
    d.rgb_entries = d.readStamps(topics.rgb);
    d.depth_entries = d.readStamps(topics.depth);
  } catch (const rosbag::BagException& e) {
    throw mc_flow::InputError("bag file '" + path + "' cannot be read: " + e.what());
  }
  d.pair();
  if (d.frames.empty()) {
    throw mc_flow::InputError("bag '" + path + "': no message on '" + topics.rgb + "' has one on '" + topics.depth +
                              "' within " + secondsText(options.max_stamp_difference) +
                              " s of its header stamp (first stamps: colour " + stampText(d.rgb_entries.front().stamp) +
                              ", depth " + stampText(d.depth_entries.front().stamp) + "; see --max-stamp-difference)");
  }
}

BagSequence::~BagSequence() = default;

std::size_t BagSequence::size() const { return impl_->frames.size(); }

std::string BagSequence::summary() const {
  const Impl& d = *impl_;
  std::ostringstream s;
  s << "bag " << d.path << ": " << d.frames.size() << " frame(s) from " << d.rgb_entries.size() << " message(s) on "
    << d.options.topics.rgb << " and " << d.depth_entries.size() << " on " << d.options.topics.depth
    << " (nearest header stamps within " << d.options.max_stamp_difference << " s); " << d.info_origin;
  return s.str();
}

BagFrame BagSequence::frame(std::size_t index) const {
  const Impl& d = *impl_;
  if (index >= d.frames.size())
    throw mc_flow::InputError("frame " + std::to_string(index) + " of a bag of " + std::to_string(d.frames.size()));
  const Entry& rgb_entry = d.rgb_entries[d.frames[index].rgb];
  const Entry& depth_entry = d.depth_entries[d.frames[index].depth];
  const std::string where = "frame " + std::to_string(index) + " (stamp " + stampText(rgb_entry.stamp) + ")";
  sensor_msgs::Image::ConstPtr rgb, depth;
  try {
    rgb = rgb_entry.message.instantiate<sensor_msgs::Image>();
    depth = depth_entry.message.instantiate<sensor_msgs::Image>();
  } catch (const rosbag::BagException& e) {
    throw mc_flow::InputError("bag file '" + d.path + "' cannot be read at " + where + ": " + e.what());
  }
  FrameInput input;
  try {
    // The nodelet's conversion: validation first, then the core's downsampling rule.
    input = toFrameInput(*rgb, *depth, d.info, d.options.downsample, d.options.max_pixels, d.options.depth_range);
  } catch (const FrameInputError& e) {
    throw FrameInputError(e.problem,
                          where + " on " + d.options.topics.rgb + " / " + d.options.topics.depth + ": " + e.what());
  }
  BagFrame out;
  out.frame.frame = std::move(input.frame);
  out.frame.K = input.K;
  out.frame.stamp = input.header.stamp.toSec();
  out.frame.source = input.header.frame_id;
  out.colour.width = input.colour.cols;
  out.colour.height = input.colour.rows;
  out.colour.channels = 3;
  const cv::Mat colour = input.colour.isContinuous() ? input.colour : input.colour.clone();
  out.colour.data.assign(colour.data, colour.data + colour.total() * 3);
  out.rgb_name = d.path + ":" + d.options.topics.rgb + "@" + stampText(rgb_entry.stamp);
  out.depth_name = d.path + ":" + d.options.topics.depth + "@" + stampText(depth_entry.stamp);
  return out;
}

}  // namespace mc_flow_ros
