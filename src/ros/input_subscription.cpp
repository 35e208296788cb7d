#include "mc_flow/ros/input_subscription.h"

#include <algorithm>

#include <image_transport/exception.h>

namespace mc_flow_ros {

namespace {

constexpr const char* kRgbTopic = "rgb/image_rect_color";
constexpr const char* kDepthTopic = "depth_registered/image_rect";
constexpr const char* kCameraInfoTopic = "rgb/camera_info";

/// Hints that select `transport` whatever the parameters say. image_transport::TransportHints reads its transport
/// from a parameter, `~image_transport` unless told otherwise; in a standalone nodelet `~` is this nodelet's private
/// namespace, so hints for the raw fallback would read the missing transport again. An empty parameter name resolves
/// to `nh`'s namespace itself, which is a dictionary or absent, never a string, so the default given here is used.
image_transport::TransportHints transportHintsFor(const std::string& transport, const ros::NodeHandle& nh) {
  return image_transport::TransportHints(transport, ros::TransportHints(), nh, "");
}

}  // namespace

TransportChoice chooseTransport(const std::string& requested, const std::vector<std::string>& loadable) {
  if (std::find(loadable.begin(), loadable.end(), "image_transport/" + requested) != loadable.end()) {
    return {requested, ""};
  }
  std::string available;
  for (const std::string& name : loadable) available += " " + name.substr(name.find('/') + 1);
  return {"raw", "image_transport '" + requested + "' is not installed (installed:" + available +
                     "): install its plug-in package or set ~image_transport to one of those; subscribing with 'raw' "
                     "instead"};
}

TransportChoice subscribeOrFallBack(const std::string& transport,
                                    const std::function<void(const std::string& transport)>& subscribe,
                                    const std::function<void()>& unsubscribe) {
  try {
    subscribe(transport);
    return {transport, ""};
  } catch (const image_transport::Exception& e) {
    // An exception out of the nodelet's onInit would make nodelet's loader destroy the nodelet after its callback
    // queues (a crash): keep a plug-in's inside.
    unsubscribe();
    const std::string error =
        "image_transport '" + transport + "' cannot subscribe (" + e.what() + "); subscribing with 'raw' instead";
    subscribe("raw");
    return {"raw", error};
  }
}

InputSubscription::InputSubscription(const ros::NodeHandle& nh, const ros::NodeHandle& private_nh)
    : nh_(nh), private_nh_(private_nh), transport_(nh) {}

std::array<std::string, 3> InputSubscription::topics() const {
  return {nh_.resolveName(kRgbTopic), nh_.resolveName(kDepthTopic), nh_.resolveName(kCameraInfoTopic)};
}

std::vector<std::string> InputSubscription::subscribe(std::uint32_t queue) {
  std::vector<std::string> errors;
  const image_transport::TransportHints asked("raw", ros::TransportHints(), private_nh_);  // ~image_transport
  const TransportChoice choice = chooseTransport(asked.getTransport(), transport_.getLoadableTransports());
  if (!choice.error.empty()) errors.push_back(choice.error);
  const TransportChoice used = subscribeOrFallBack(
      choice.transport,
      [&](const std::string& transport) {
        const image_transport::TransportHints hints =
            transport == asked.getTransport() ? asked : transportHintsFor(transport, private_nh_);
        rgb_.subscribe(transport_, kRgbTopic, queue, hints);
        depth_.subscribe(transport_, kDepthTopic, queue, hints);
      },
      [this] {
        rgb_.unsubscribe();
        depth_.unsubscribe();
      });
  if (!used.error.empty()) errors.push_back(used.error);
  info_.subscribe(nh_, kCameraInfoTopic, queue);
  return errors;
}

void InputSubscription::unsubscribe() {
  rgb_.unsubscribe();
  depth_.unsubscribe();
  info_.unsubscribe();
}

}  // namespace mc_flow_ros
