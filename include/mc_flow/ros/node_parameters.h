/**
 * @file node_parameters.h
 * @brief The nodelet's own parameters (its private namespace), generated from node_parameters.def: the struct, its
 * defaults as text, the bounds check and the start-up description. ROS-free, so that all of it is unit-tested; the
 * nodelet reads them with readNodeParameters (node_parameter_reading.h). The solver's parameters are mc_flow::Config's
 * (dynamic_reconfigure).
 */
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "mc_flow/core/buffer_layout.h"

namespace mc_flow_ros {

/// @brief One row of node_parameters.def, for tests and documentation.
struct NodeParameterInfo {
  std::string name;
  std::string default_text;  ///< as the launch file spells it ("" for an empty text, numbers as C++ prints them)
  std::string unit;          ///< "" for flags, texts and unitless numbers
  std::string description;
};

struct NodeParameters {
#define MCFLOW_NODE_NUMBER(type, name, default_value, lowest, highest, unit, description) type name = default_value;
#define MCFLOW_NODE_FLAG(name, default_value, description) bool name = default_value;
#define MCFLOW_NODE_TEXT(name, default_value, description) std::string name = default_value;
#include "mc_flow/ros/node_parameters.def"
#undef MCFLOW_NODE_NUMBER
#undef MCFLOW_NODE_FLAG
#undef MCFLOW_NODE_TEXT

  /// @brief Every parameter as (name, default as text), in the table's order.
  static std::vector<std::pair<std::string, std::string>> defaults();
  /// @brief Every row of the table, in its order.
  static std::vector<NodeParameterInfo> table();

  /// @brief Brings every value into its bounds and rules (numbers clamped to the table's bounds, downsample a power of
  /// two or 0, cloud_colour one of its words) and returns one warning per change, naming the parameter, the value and
  /// what is used instead; also warns about combinations that work but are probably not meant (publish_odom_tf without
  /// base_frame, prior_frame equal to the odom frame this node broadcasts). Does not touch the file system.
  std::vector<std::string> sanitise();

  /// @brief "name=value unit ..." for the start-up log, in the table's order.
  std::string describe() const;
};

}  // namespace mc_flow_ros
