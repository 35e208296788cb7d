#include "mc_flow/ros/input_watch.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

namespace mc_flow_ros {

std::string secondsText(bool known, double seconds) {
  if (!known) return "none";
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%.6f", seconds);
  return buffer;
}

namespace {

std::string wholeSeconds(double s) { return std::to_string(static_cast<long>(std::floor(std::max(s, 0.0)))); }

std::string signedSeconds(double s) {
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%+.3f s", s);
  return buffer;
}

std::string joinLabels(const std::vector<const WatchedTopic*>& topics) {
  std::string out;
  for (std::size_t i = 0; i < topics.size(); ++i) {
    if (i > 0) out += i + 1 == topics.size() ? " and " : ", ";
    out += topics[i]->topic;
  }
  return out;
}

std::string counts(const InputSnapshot& s) {
  return std::to_string(s.topics[0].received) + "/" + std::to_string(s.topics[1].received) + "/" +
         std::to_string(s.topics[2].received) + " rgb/depth/camera_info messages received";
}

}  // namespace

std::optional<InputWarning> describeInputSilence(const InputSnapshot& s, double warn_after) {
  if (!(s.seconds_without_sync > warn_after)) return std::nullopt;
  const std::string silent = wholeSeconds(s.seconds_without_sync);

  std::vector<const WatchedTopic*> never, stopped, arriving;
  for (const WatchedTopic& t : s.topics) {
    if (t.received == 0)
      never.push_back(&t);
    else if (t.seconds_since_last > warn_after)
      stopped.push_back(&t);
    else
      arriving.push_back(&t);
  }

  std::ostringstream text;
  if (!never.empty()) {
    text << "no synchronised input for " << silent << " s. Waiting for ";
    for (int i = 0; i < 3; ++i) {
      text << s.topics[i].topic << " (" << s.topics[i].received << " received)"
           << (i == 0   ? ", "
               : i == 1 ? " and "
                        : "");
    }
    text << ": nothing at all on " << joinLabels(never)
         << ". Check that all three are published (rostopic hz) and remapped to these names";
    bool info_missing = false;
    for (const WatchedTopic* t : never) info_missing = info_missing || t == &s.topics[2];
    if (info_missing) text << "; a missing camera_info is the most common cause";
    return InputWarning{InputSilence::NeverArrived, "no_input", text.str(), false};
  }

  if (!stopped.empty()) {
    double newest = stopped.front()->seconds_since_last;
    for (const WatchedTopic* t : stopped) newest = std::min(newest, t->seconds_since_last);
    if (arriving.empty()) {
      const WatchedTopic& rgb = s.topics[0];
      text << "no input for " << wholeSeconds(newest) << " s; " << counts(s)
           << ", last at t = " << secondsText(rgb.has_stamp, rgb.stamp) << " (stamp of the last rgb image)"
           << ": the input stopped (a bag that ended, or a camera driver that stopped publishing)";
    } else {
      text << "no input on " << joinLabels(stopped) << " for " << wholeSeconds(newest) << " s while "
           << joinLabels(arriving) << (arriving.size() > 1 ? " still arrive" : " still arrives") << "; " << counts(s)
           << ". Last stamps:";
      for (const WatchedTopic* t : stopped) text << " " << t->label << " t = " << secondsText(t->has_stamp, t->stamp);
      text << ": that input stopped; nothing synchronises without it";
    }
    return InputWarning{InputSilence::Stopped, "input_stopped", text.str(), false};
  }

  // Every topic delivers, yet nothing synchronises: say how far the stamps are apart.
  const WatchedTopic &rgb = s.topics[0], &depth = s.topics[1], &info = s.topics[2];
  text << "messages arrive on all inputs (" << counts(s) << ") but none were synchronised for " << silent
       << " s. Latest stamps: rgb " << secondsText(rgb.has_stamp, rgb.stamp) << ", depth "
       << secondsText(depth.has_stamp, depth.stamp) << ", camera_info " << secondsText(info.has_stamp, info.stamp);
  if (rgb.has_stamp && depth.has_stamp && info.has_stamp) {
    const double rgb_depth = rgb.stamp - depth.stamp, rgb_info = rgb.stamp - info.stamp;
    text << " (rgb - depth " << signedSeconds(rgb_depth) << ", rgb - camera_info " << signedSeconds(rgb_info) << ")";
    const double worst = std::max(std::abs(rgb_depth), std::abs(rgb_info));
    if (!s.approximate_sync && worst > 0) {
      text << ": exact synchronisation needs equal stamps; set approximate_sync:=true";
    } else if (s.approximate_sync && s.approximate_sync_max_interval > 0 && worst > s.approximate_sync_max_interval) {
      text << ": more than approximate_sync_max_interval " << secondsText(true, s.approximate_sync_max_interval)
           << " s apart; raise it or fix the stamps";
    } else {
      text << ": check that the three are stamped from the same clock";
    }
  }
  text << ". Restarting the synchroniser";
  return InputWarning{InputSilence::NotSynchronised, "resync", text.str(), true};
}

}  // namespace mc_flow_ros
