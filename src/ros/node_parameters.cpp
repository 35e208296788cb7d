#include "mc_flow/ros/node_parameters.h"

#include <algorithm>
#include <sstream>

#include "mc_flow/ros/node_parameter_reading.h"

namespace mc_flow_ros {

namespace {

std::string text(int v) { return std::to_string(v); }
std::string text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
std::string text(bool v) { return v ? "true" : "false"; }
std::string text(const std::string& v) { return v; }

// Clamps `value` into [lowest, highest] and says so.
template <class T>
void clampInto(const char* name, T& value, T lowest, T highest, const char* unit, std::vector<std::string>& warnings) {
  if (value >= lowest && value <= highest) return;  // also false for NaN
  const T used = value > highest ? highest : lowest;
  const std::string u = *unit ? std::string(" ") + unit : std::string();
  warnings.push_back(std::string(name) + " " + text(value) + u + " is outside [" + text(lowest) + ", " + text(highest) +
                     "]" + u + "; using " + text(used));
  value = used;
}

}  // namespace

std::vector<std::pair<std::string, std::string>> NodeParameters::defaults() {
  std::vector<std::pair<std::string, std::string>> out;
  for (const NodeParameterInfo& row : table()) out.emplace_back(row.name, row.default_text);
  return out;
}

std::vector<NodeParameterInfo> NodeParameters::table() {
  const NodeParameters d;
  return {
#define MCFLOW_NODE_NUMBER(type, name, default_value, lowest, highest, unit, description) \
  {#name, text(d.name), unit, description},
#define MCFLOW_NODE_FLAG(name, default_value, description) {#name, text(d.name), "", description},
#define MCFLOW_NODE_TEXT(name, default_value, description) {#name, text(d.name), "", description},
#include "mc_flow/ros/node_parameters.def"
#undef MCFLOW_NODE_NUMBER
#undef MCFLOW_NODE_FLAG
#undef MCFLOW_NODE_TEXT
  };
}

std::vector<std::string> NodeParameters::sanitise() {
  std::vector<std::string> warnings;
#define MCFLOW_NODE_NUMBER(type, name, default_value, lowest, highest, unit, description) \
  clampInto<type>(#name, name, lowest, highest, unit, warnings);
#define MCFLOW_NODE_FLAG(name, default_value, description)
#define MCFLOW_NODE_TEXT(name, default_value, description)
#include "mc_flow/ros/node_parameters.def"
#undef MCFLOW_NODE_NUMBER
#undef MCFLOW_NODE_FLAG
#undef MCFLOW_NODE_TEXT
  if ((downsample & (downsample - 1)) != 0) {
    warnings.push_back("downsample " + text(downsample) + " is not 0 (automatic) or a power of two; using 0");
    downsample = 0;
  }
  if (cloud_colour != "segment" && cloud_colour != "image") {
    warnings.push_back("cloud_colour '" + cloud_colour + "' is neither 'segment' nor 'image'; using 'segment'");
    cloud_colour = "segment";
  }
  if (publish_odom_tf && base_frame.empty())
    warnings.push_back(
        "publish_odom_tf without base_frame broadcasts " + odom_frame +
        " -> the camera's optical frame, which usually has a parent in the camera's TF tree already: set "
        "base_frame to the robot's base frame");
  if (!prior_frame.empty() && prior_frame == odom_frame && publish_odom_tf)
    warnings.push_back("prior_frame '" + prior_frame +
                       "' is the odom_frame this node broadcasts: its own odometry would be its prior; set prior_frame "
                       "to another source's frame");
  return warnings;
}

std::string NodeParameters::describe() const {
  std::ostringstream s;
  const char* separator = "";
#define MCFLOW_NODE_NUMBER(type, name, default_value, lowest, highest, unit, description) \
  s << separator << #name "=" << text(name) << (*unit ? " " unit : "");                   \
  separator = " ";
#define MCFLOW_NODE_FLAG(name, default_value, description) \
  s << separator << #name "=" << text(name);               \
  separator = " ";
#define MCFLOW_NODE_TEXT(name, default_value, description) \
  s << separator << #name "='" << name << "'";             \
  separator = " ";
#include "mc_flow/ros/node_parameters.def"
#undef MCFLOW_NODE_NUMBER
#undef MCFLOW_NODE_FLAG
#undef MCFLOW_NODE_TEXT
  return s.str();
}

NodeParameters readNodeParameters(const ros::NodeHandle& private_nh) {
  NodeParameters p;
#define MCFLOW_NODE_NUMBER(type, name, default_value, lowest, highest, unit, description) \
  private_nh.param(#name, p.name, p.name);
#define MCFLOW_NODE_FLAG(name, default_value, description) private_nh.param(#name, p.name, p.name);
#define MCFLOW_NODE_TEXT(name, default_value, description) private_nh.param(#name, p.name, p.name);
#include "mc_flow/ros/node_parameters.def"
#undef MCFLOW_NODE_NUMBER
#undef MCFLOW_NODE_FLAG
#undef MCFLOW_NODE_TEXT
  return p;
}

}  // namespace mc_flow_ros
