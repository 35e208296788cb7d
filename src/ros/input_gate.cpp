#include "mc_flow/ros/input_gate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace mc_flow_ros {

namespace {
constexpr double kRateWindowSeconds = 10.0;
const char* const kLabels[3] = {"rgb", "depth", "camera_info"};
}  // namespace

std::string stampText(const ros::Time& t) {
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%u.%09u", t.sec, t.nsec);
  return buffer;
}

std::optional<std::string> stampDifferenceWarning(const ros::Time& rgb, const ros::Time& depth, double max_difference) {
  const double difference = std::abs((rgb - depth).toSec());
  if (!(difference > max_difference)) return std::nullopt;
  return "RGB stamp " + stampText(rgb) + " and depth stamp " + stampText(depth) + " differ by " +
         std::to_string(difference) + " s (> max_stamp_difference " + std::to_string(max_difference) +
         " s): motion between them biases the result; check the camera's sync settings";
}

InputGate::InputGate(std::array<std::string, 3> topics) : topics_(std::move(topics)) {}

InputGate::Admission InputGate::admit(int topic, const std_msgs::Header& header, ros::WallTime now) {
  const ros::Time& stamp = header.stamp;
  ros::Time last;
  Admission admission;
  long held = 0;
  bool straggler = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++received_[topic];
    // roscpp numbers each message of a publisher: a gap of a few is what the subscriber queue dropped; a large
    // jump (publisher restarted, other publisher) is not counted.
    const std::uint32_t previous_seq = last_seq_[topic];
    if (previous_seq != 0 && header.seq > previous_seq + 1 && header.seq - previous_seq < 1000) {
      lost_before_callback_[topic] += long(header.seq - previous_seq - 1);
    }
    last_seq_[topic] = header.seq;
    last = last_stamp_[topic];
    if (last.isZero() && !before_restart_[topic].isZero()) {
      // The first message on this topic since another topic restarted the stream. At or beyond where this topic had
      // got to, and soon after the restart, it was sent before the restart: admitting it would make it the topic's
      // start and hold back the new stream, whose stamps are lower, until the next restart is allowed.
      straggler = stamp >= before_restart_[topic] && (now - last_restart_).toSec() < kStragglerSeconds;
      if (straggler) {
        last = before_restart_[topic];
      } else {
        before_restart_[topic] = ros::Time();
      }
    }
    if (!straggler && (last.isZero() || stamp > last)) {
      last_stamp_[topic] = stamp;
      return admission;
    }
    admission.restart_synchroniser =
        !straggler && stamp < last &&
        (last_restart_.isZero() || (now - last_restart_).toSec() >= kMinSecondsBetweenRestarts);
    if (admission.restart_synchroniser) {
      last_restart_ = now;
      ++restarts_;
      for (int i = 0; i < 3; ++i) {
        before_restart_[i] = i == topic ? ros::Time() : last_stamp_[i];
        last_stamp_[i] = ros::Time();
      }
      last_stamp_[topic] = stamp;
    } else {
      held = ++held_back_[topic];
      admission.pass = false;
    }
  }
  const std::string& name = topics_[topic];
  const std::string what =
      name + ": stamp " + stampText(stamp) +
      (straggler       ? " was sent before the stream restarted (this topic had reached " + stampText(last) + ")"
       : stamp == last ? " repeats the previous message's"
                       : " went back from " + stampText(last));
  if (admission.restart_synchroniser) {
    // A driver restart or a bag replayed without /clock: the synchroniser's queues hold the old stream.
    admission.warning_key = "input_stamp:restart " + name;
    admission.warning = what + ": restarting the synchroniser";
  } else {
    admission.warning_key = "input_stamp:" + name;
    admission.warning =
        what + ": message held back from the synchroniser (" + std::to_string(held) + " on this topic so far)";
  }
  return admission;
}

void InputGate::subscribed(ros::WallTime now) {
  std::lock_guard<std::mutex> lock(mutex_);
  subscribed_since_ = now;
}

void InputGate::synchronised(ros::WallTime now) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++frames_synced_;
  last_sync_time_ = now;
  std::copy(received_, received_ + 3, received_at_sync_);
  sync_times_.push_back(now);
  while (!sync_times_.empty() && (now - sync_times_.front()).toSec() > kRateWindowSeconds) sync_times_.pop_front();
}

InputGate::Watch InputGate::watch(ros::WallTime now, bool approximate_sync, double approximate_sync_max_interval,
                                  double warn_after) {
  std::lock_guard<std::mutex> lock(mutex_);
  // Arrival times are this watch's: a count that changed since the last tick.
  InputSnapshot snapshot;
  snapshot.seconds_without_sync = (now - std::max(last_sync_time_, subscribed_since_)).toSec();
  snapshot.approximate_sync = approximate_sync;
  snapshot.approximate_sync_max_interval = approximate_sync_max_interval;
  bool new_since_sync = true;
  for (int i = 0; i < 3; ++i) {
    if (received_[i] != received_at_watch_[i] || last_arrival_[i] < subscribed_since_) {
      last_arrival_[i] = received_[i] != received_at_watch_[i] ? now : subscribed_since_;
      received_at_watch_[i] = received_[i];
    }
    WatchedTopic& t = snapshot.topics[i];
    t.label = kLabels[i];
    t.topic = topics_[i];
    t.received = received_[i];
    t.seconds_since_last = (now - last_arrival_[i]).toSec();
    t.has_stamp = !last_stamp_[i].isZero();
    t.stamp = last_stamp_[i].toSec();
    new_since_sync = new_since_sync && received_[i] > received_at_sync_[i];
  }
  Watch watch;
  watch.warning = describeInputSilence(snapshot, warn_after);
  if (watch.warning && watch.warning->restart_synchroniser) {
    if (!new_since_sync) {
      watch.warning.reset();  // said already; nothing new arrived on some topic since
    } else {
      // A synchroniser confused by an irregular stream (dropped or skewed messages) can stay stuck: start it afresh.
      watch.restart_synchroniser = true;
      std::copy(received_, received_ + 3, received_at_sync_);
      ++restarts_;
    }
  }
  return watch;
}

bool InputGate::silent(ros::WallTime now, double warn_after) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return (now - std::max(last_sync_time_, subscribed_since_)).toSec() > warn_after;
}

long InputGate::framesSynchronised() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return frames_synced_;
}

void InputGate::addTo(diagnostic_updater::DiagnosticStatusWrapper& status, ros::WallTime now) const {
  std::lock_guard<std::mutex> lock(mutex_);
  while (!sync_times_.empty() && (now - sync_times_.front()).toSec() > kRateWindowSeconds) sync_times_.pop_front();
  double rate = 0;
  if (sync_times_.size() >= 2) {
    rate = double(sync_times_.size() - 1) / std::max((sync_times_.back() - sync_times_.front()).toSec(), 1e-6);
  }
  auto three = [](const long* v) {
    return std::to_string(v[0]) + " / " + std::to_string(v[1]) + " / " + std::to_string(v[2]);
  };
  status.add("input rate [Hz]", rate);
  status.add("frames synchronised", frames_synced_);
  status.add("received rgb / depth / camera_info", three(received_));
  status.add("lost before the callbacks rgb / depth / camera_info (header.seq gaps)", three(lost_before_callback_));
  status.add("held back (repeated or backward stamps) rgb / depth / camera_info", three(held_back_));
  status.add("synchroniser restarts", restarts_);
}

}  // namespace mc_flow_ros
