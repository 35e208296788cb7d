/**
 * @file node_parameter_reading.h
 * @brief Reads NodeParameters from a nodelet's private namespace (each missing parameter keeps its default).
 */
#pragma once

#include <ros/node_handle.h>

#include "mc_flow/ros/node_parameters.h"

namespace mc_flow_ros {

/// @brief The parameters in `private_nh` over the defaults, not yet sanitised (NodeParameters::sanitise).
NodeParameters readNodeParameters(const ros::NodeHandle& private_nh);

}  // namespace mc_flow_ros
