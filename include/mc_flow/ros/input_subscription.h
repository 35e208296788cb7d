/**
 * @file input_subscription.h
 * @brief The nodelet's three input subscribers (colour and depth through image_transport, camera_info) and the choice
 * of their transport: `~image_transport`'s, or raw when that plug-in is not installed or cannot subscribe, so that a
 * missing plug-in is an error in the log instead of an exception that takes the manager (and the camera) down. The
 * choice is made by pure functions (chooseTransport, subscribeOrFallBack), unit-tested without a node
 * (test/ros/test_input_subscription.cpp); test/ros/check_transport_fallback.sh checks it in a standalone nodelet.
 */
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>

namespace mc_flow_ros {

/// @brief The transport to subscribe with and, when it is not the one asked for, why (an error for the log).
struct TransportChoice {
  std::string transport;
  std::string error;  ///< empty: the transport asked for is used
};

/// @brief `requested` when its plug-in is among `loadable` (image_transport's lookup names, "image_transport/raw",
/// ...); else raw, with an error naming the missing transport and the installed ones.
TransportChoice chooseTransport(const std::string& requested, const std::vector<std::string>& loadable);

/// @brief Calls `subscribe(transport)`. A plug-in that is declared and loads but cannot subscribe throws
/// image_transport::Exception: then `unsubscribe()`, an error naming the transport and the reason, and
/// `subscribe("raw")` (whose exceptions are not caught).
TransportChoice subscribeOrFallBack(const std::string& transport,
                                    const std::function<void(const std::string& transport)>& subscribe,
                                    const std::function<void()>& unsubscribe);

class InputSubscription {
 public:
  /// @brief The inputs are `nh`'s relative topics rgb/image_rect_color, depth_registered/image_rect and
  /// rgb/camera_info (remapped in launch files); `~image_transport` is read from `private_nh`.
  InputSubscription(const ros::NodeHandle& nh, const ros::NodeHandle& private_nh);

  /// @brief The resolved names of the rgb, depth and camera_info inputs (InputGate's order).
  std::array<std::string, 3> topics() const;

  /// @brief Subscribes the three inputs with `queue` messages each (see chooseTransport and subscribeOrFallBack) and
  /// returns the errors to log (none when the transport asked for subscribed).
  std::vector<std::string> subscribe(std::uint32_t queue);
  void unsubscribe();

  /// @brief The subscribers, for their callbacks (registerCallback).
  image_transport::SubscriberFilter& rgb() { return rgb_; }
  image_transport::SubscriberFilter& depth() { return depth_; }
  message_filters::Subscriber<sensor_msgs::CameraInfo>& info() { return info_; }

 private:
  ros::NodeHandle nh_, private_nh_;
  image_transport::ImageTransport transport_;  // before the subscribers: they go first
  image_transport::SubscriberFilter rgb_, depth_;
  message_filters::Subscriber<sensor_msgs::CameraInfo> info_;
};

}  // namespace mc_flow_ros
