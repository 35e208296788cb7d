// A test host of mc_flow/MCFlowNodelet: the nodelet in a process of its own whose first solve backend gets an injected
// fault (mc_flow/testing/fault_injection.h), so that the rostests drive the nodelet's GPU-fault path
// (backend_fault.test) and hold a solve on any machine (lazy_and_drops.test). The product has no such hook; this
// executable is built with the tests only and is not installed.
//   nodelet_with_fault --fault SOLVE[:STAGE[:hold=MS]] [ROS remappings and __name:=...]
#include <cstdio>
#include <string>
#include <vector>

#include <ros/ros.h>

#include "mc_flow/ros/mc_flow_nodelet.h"
#include "mc_flow/testing/fault_injection.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "mc_flow");
  std::vector<std::string> args;
  ros::removeROSArgs(argc, argv, args);
  std::string fault;
  for (std::size_t i = 1; i + 1 < args.size(); ++i)
    if (args[i] == "--fault") fault = args[i + 1];
  if (fault.empty()) {
    std::fprintf(stderr, "usage: nodelet_with_fault --fault SOLVE[:STAGE[:hold=MS]]\n");
    return 2;
  }
  try {
    mc_flow_ros::MCFlowNodelet nodelet(mc_flow::faultOnFirstBackend(mc_flow::parseBackendFault(fault)));
    // The node's own name and namespace, as a manager gives a nodelet loaded under this name; callbacks on the global
    // queue, served by one thread (a nodelet's callbacks are serialised).
    nodelet.init(ros::this_node::getName(), ros::M_string(), nodelet::V_string());
    ros::spin();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nodelet_with_fault: %s\n", e.what());
    return 1;
  }
  return 0;
}
