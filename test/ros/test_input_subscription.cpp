// The input subscription's choice of transport without a node: a missing plug-in, one that cannot subscribe
// (test/ros/check_transport_fallback.sh checks the same in a standalone nodelet).
#include <gtest/gtest.h>

#include <image_transport/exception.h>

#include "mc_flow/ros/input_subscription.h"

namespace mc_flow_ros {
namespace {

const std::vector<std::string> kInstalled = {"image_transport/raw", "image_transport/compressed"};

TEST(InputSubscription, AnInstalledTransportIsUsed) {
  for (const std::string& transport : {"raw", "compressed"}) {
    const TransportChoice choice = chooseTransport(transport, kInstalled);
    EXPECT_EQ(choice.transport, transport);
    EXPECT_EQ(choice.error, "");
  }
}

TEST(InputSubscription, AMissingTransportIsNamedWithTheInstalledOnesAndRawIsUsed) {
  const TransportChoice choice = chooseTransport("theora", kInstalled);
  EXPECT_EQ(choice.transport, "raw");
  EXPECT_EQ(choice.error,
            "image_transport 'theora' is not installed (installed: raw compressed): install its plug-in package or "
            "set ~image_transport to one of those; subscribing with 'raw' instead");
  // Only "image_transport/NAME" is NAME's plug-in.
  EXPECT_EQ(chooseTransport("compressed", {"image_transport/raw", "other/compressed"}).transport, "raw");
}

TEST(InputSubscription, ATransportThatSubscribesIsKept) {
  std::vector<std::string> calls;
  int unsubscribed = 0;
  const TransportChoice used = subscribeOrFallBack(
      "compressed", [&](const std::string& transport) { calls.push_back(transport); }, [&] { ++unsubscribed; });
  EXPECT_EQ(used.transport, "compressed");
  EXPECT_EQ(used.error, "");
  EXPECT_EQ(calls, std::vector<std::string>{"compressed"});
  EXPECT_EQ(unsubscribed, 0);
}

TEST(InputSubscription, APlugInThatCannotSubscribeIsUndoneNamedAndRawIsUsed) {
  std::vector<std::string> calls;
  int unsubscribed = 0;
  const TransportChoice used = subscribeOrFallBack(
      "theora",
      [&](const std::string& transport) {
        calls.push_back(transport);
        if (transport == "theora") throw image_transport::Exception("no decoder");
      },
      [&] { ++unsubscribed; });
  EXPECT_EQ(used.transport, "raw");
  EXPECT_EQ(used.error, "image_transport 'theora' cannot subscribe (no decoder); subscribing with 'raw' instead");
  EXPECT_EQ(calls, (std::vector<std::string>{"theora", "raw"}));
  EXPECT_EQ(unsubscribed, 1);
}

TEST(InputSubscription, OnlyTheFirstFailureFallsBack) {
  const auto failing = [](const std::string& transport) { throw image_transport::Exception(transport + " failed"); };
  EXPECT_THROW(subscribeOrFallBack("theora", failing, [] {}), image_transport::Exception);
  // Other exceptions are not a plug-in's: they are not caught.
  EXPECT_THROW(subscribeOrFallBack(
                   "theora", [](const std::string&) { throw std::runtime_error("not a plug-in's"); }, [] {}),
               std::runtime_error);
}

}  // namespace
}  // namespace mc_flow_ros
