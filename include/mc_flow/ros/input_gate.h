/**
 * @file input_gate.h
 * @brief The nodelet's inputs between the subscribers and the synchroniser: what reaches the synchroniser (only
 * increasing stamps per topic; a jump back restarts the stream), what arrived and what was lost, and what to say
 * when synchronised frames stop (describeInputSilence). Thread-safe; times are passed in, so that every rule is
 * unit-tested without a node (test/ros/test_input_gate.cpp).
 */
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <string>

#include <diagnostic_updater/DiagnosticStatusWrapper.h>
#include <ros/time.h>
#include <std_msgs/Header.h>

#include "mc_flow/ros/input_watch.h"

namespace mc_flow_ros {

class InputGate {
 public:
  enum Topic { kRgb = 0, kDepth = 1, kCameraInfo = 2 };
  /// A jump back restarts the synchroniser at most this often; backward stamps in between are held back, so a storm
  /// of them cannot keep re-arming message_filters' warnings.
  static constexpr double kMinSecondsBetweenRestarts = 5.0;
  /// For this long after a restart, a message on another topic at or beyond the stamp that topic had reached is a
  /// straggler of the old stream (each topic has its own connection, so the new stream's first message on one topic
  /// can overtake the old stream's last on another) and is held back instead of becoming the topic's new start.
  static constexpr double kStragglerSeconds = 1.0;

  /// What to do with one message.
  struct Admission {
    bool pass = true;                   ///< hand it to the synchroniser
    bool restart_synchroniser = false;  ///< the stream went back: rebuild the synchroniser first, then pass it
    std::string warning_key, warning;   ///< non-empty: warn (throttled by key)
  };

  /// What the once-a-second watch found (no synchronised frame for a while).
  struct Watch {
    std::optional<InputWarning> warning;
    bool restart_synchroniser = false;  ///< every topic arrives but nothing synchronises: start it afresh
  };

  /// `topics`: the resolved names of the rgb, depth and camera_info inputs (for the words).
  explicit InputGate(std::array<std::string, 3> topics);

  const std::string& topic(int index) const { return topics_[index]; }

  /// @brief Counts the arrival (and header.seq gaps: messages lost before the callback) and decides whether the
  /// message reaches the synchroniser: stamps that repeat or go back are held back, except that a jump back restarts
  /// the stream (at most every kMinSecondsBetweenRestarts), so the synchroniser only ever sees increasing stamps. After
  /// a restart, the old stream's stragglers on the other topics are held back too (kStragglerSeconds).
  Admission admit(int topic, const std_msgs::Header& header, ros::WallTime now);
  /// @brief The inputs were (re)subscribed at `now`: silence is measured from here.
  void subscribed(ros::WallTime now);
  /// @brief A synchronised frame left the synchroniser at `now`.
  void synchronised(ros::WallTime now);

  /// @brief Called once a second while subscribed: the silence warning, if any. A synchroniser that sees every topic
  /// but never fires is restarted at most once per new message on every topic (the restart is counted here).
  Watch watch(ros::WallTime now, bool approximate_sync, double approximate_sync_max_interval, double warn_after);

  /// @brief True when subscribed inputs gave no synchronised frame for more than `warn_after` seconds.
  bool silent(ros::WallTime now, double warn_after) const;
  long framesSynchronised() const;
  /// @brief The input's part of the nodelet's diagnostics: rate, counts per topic, losses, held back, restarts.
  void addTo(diagnostic_updater::DiagnosticStatusWrapper& status, ros::WallTime now) const;

 private:
  std::array<std::string, 3> topics_;
  mutable std::mutex mutex_;
  mutable std::deque<ros::WallTime> sync_times_;  // arrivals of synchronised frames (last 10 s)
  ros::WallTime last_sync_time_, subscribed_since_, last_restart_;
  long frames_synced_ = 0;
  long received_[3] = {0, 0, 0};
  ros::Time last_stamp_[3];      // last stamp admitted per topic (zero after a restart)
  ros::Time before_restart_[3];  // the stamp each topic had reached at the last restart (zero once it rejoined)
  std::uint32_t last_seq_[3] = {0, 0, 0};
  long lost_before_callback_[3] = {0, 0, 0};  // header.seq gaps
  long held_back_[3] = {0, 0, 0};             // repeated or backward stamps not passed to the synchroniser
  long restarts_ = 0;
  long received_at_sync_[3] = {0, 0, 0};   // per-topic arrivals at the last synchronised frame (or restart)
  long received_at_watch_[3] = {0, 0, 0};  // at the watch's last tick
  ros::WallTime last_arrival_[3];          // when the watch last saw each count change (its resolution: 1 s)
};

/// "1234.500000000" (seconds and nanoseconds of a stamp).
std::string stampText(const ros::Time& t);

/// @brief The warning for a synchronised pair whose RGB and depth stamps differ by more than `max_difference` [s]
/// (max_stamp_difference), naming both stamps; nothing when they are closer.
std::optional<std::string> stampDifferenceWarning(const ros::Time& rgb, const ros::Time& depth, double max_difference);

}  // namespace mc_flow_ros
