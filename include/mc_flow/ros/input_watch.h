#pragma once
/**
 * @brief What to say when no synchronised frame has arrived for a while: the input never arrived, it
 * stopped (a bag that ended, a driver that died), or it arrives but does not synchronise. ROS-free and
 * pure, so that every text is tested without a node; the nodelet's timer fills the snapshot.
 */
#include <optional>
#include <string>

namespace mc_flow_ros {

/// One input topic as the nodelet's timer sees it.
struct WatchedTopic {
  std::string label;              ///< "rgb", "depth", "camera_info"
  std::string topic;              ///< resolved topic name
  long received = 0;              ///< messages received since start
  double seconds_since_last = 0;  ///< [s, wall] since the last message (or since subscribing, if none)
  bool has_stamp = false;         ///< the last admitted message's stamp is known
  double stamp = 0;               ///< [s] header.stamp of the last admitted message
};

struct InputSnapshot {
  WatchedTopic topics[3];           ///< rgb, depth, camera_info
  double seconds_without_sync = 0;  ///< [s, wall] since the last synchronised frame (or since subscribing)
  bool approximate_sync = true;
  double approximate_sync_max_interval = 0;  ///< [s], 0 = no limit
};

enum class InputSilence { NeverArrived, Stopped, NotSynchronised };

struct InputWarning {
  InputSilence problem;
  std::string key;                    ///< throttling key for warnThrottled ("no_input", "input_stopped", "resync")
  std::string text;                   ///< the warning, naming topics, counts, stamps and durations
  bool restart_synchroniser = false;  ///< a synchroniser that sees every topic but never fires is restarted
};

/**
 * @brief The warning for a snapshot, or nothing while synchronised frames arrive (seconds_without_sync
 * at most `warn_after`). A topic counts as "arriving" when its last message is at most `warn_after` old.
 * - some topic has received nothing: NeverArrived, naming what each topic received;
 * - no topic arrives any more: Stopped ("no input for 16 s; 20/20/20 frames received, last at t");
 *   some topics stopped while others arrive: Stopped, naming the ones that stopped;
 * - every topic arrives but nothing synchronises: NotSynchronised, with how far the latest stamps differ.
 */
std::optional<InputWarning> describeInputSilence(const InputSnapshot& snapshot, double warn_after);

/// "1234.500000" (seconds, six decimals) or "none".
std::string secondsText(bool known, double seconds);

}  // namespace mc_flow_ros
