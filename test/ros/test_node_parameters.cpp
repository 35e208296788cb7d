// The nodelet's parameter table (include/mc_flow/ros/node_parameters.def): every parameter appears once in
// launch/mc_flow.launch, as an argument whose default and unit are the table's and as a parameter set from that
// argument; out-of-bounds values are brought back with a warning naming them.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <regex>
#include <sstream>

#include "mc_flow/ros/node_parameters.h"

#ifndef MCFLOW_LAUNCH_DIR
#error "MCFLOW_LAUNCH_DIR must name the launch folder"
#endif

namespace {

std::string launchText() {
  std::ifstream in(std::string(MCFLOW_LAUNCH_DIR) + "/mc_flow.launch");
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

int count(const std::string& text, const std::string& needle) {
  int n = 0;
  for (std::size_t at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) ++n;
  return n;
}

// Numbers compare by value ("1.0" is 1), everything else as text; the launch file spells "" as none.
bool sameDefault(const std::string& launch, const std::string& code) {
  if (launch == "none" && code.empty()) return true;
  char* end_a = nullptr;
  char* end_b = nullptr;
  const double a = std::strtod(launch.c_str(), &end_a), b = std::strtod(code.c_str(), &end_b);
  if (!launch.empty() && !code.empty() && *end_a == '\0' && *end_b == '\0') return a == b;
  return launch == code;
}

TEST(NodeParameters, EachAppearsOnceInTheLaunchFileWithTheNodeletsDefault) {
  const std::string text = launchText();
  ASSERT_FALSE(text.empty()) << "cannot read " << MCFLOW_LAUNCH_DIR << "/mc_flow.launch";
  for (const auto& [name, value] : mc_flow_ros::NodeParameters::defaults()) {
    SCOPED_TRACE(name);
    const std::regex arg("<arg name=\"" + name + "\" default=\"([^\"]*)\"");
    std::smatch m;
    ASSERT_TRUE(std::regex_search(text, m, arg)) << "no <arg name=\"" << name << "\" default=...>";
    EXPECT_TRUE(sameDefault(m[1].str(), value))
        << "launch default '" << m[1].str() << "', nodelet default '" << value << "'";
    EXPECT_EQ(count(text, "<arg name=\"" + name + "\""), 1);
    EXPECT_EQ(count(text, "<param name=\"" + name + "\""), 1);
  }
}

TEST(NodeParameters, EachLaunchArgumentStatesTheTablesUnit) {
  const std::string text = launchText();
  for (const mc_flow_ros::NodeParameterInfo& row : mc_flow_ros::NodeParameters::table()) {
    SCOPED_TRACE(row.name);
    const std::regex arg("<arg name=\"" + row.name + "\" default=\"[^\"]*\" doc=\"([^\"]*)\"");
    std::smatch m;
    ASSERT_TRUE(std::regex_search(text, m, arg)) << "no doc for " << row.name;
    EXPECT_FALSE(row.description.empty());
    if (!row.unit.empty()) EXPECT_EQ(m[1].str().rfind("[" + row.unit + "]", 0), 0u) << m[1].str();
  }
}

TEST(NodeParameters, ValuesOutsideTheirBoundsAreBroughtBackWithAWarningNamingThem) {
  mc_flow_ros::NodeParameters defaults;
  EXPECT_TRUE(defaults.sanitise().empty());

  mc_flow_ros::NodeParameters p;
  p.queue_size = 0;
  p.segmentation_blend = 1.5;
  p.downsample = 3;
  p.cloud_colour = "rainbow";
  p.max_pair_interval = -1;
  const std::vector<std::string> warnings = p.sanitise();
  EXPECT_EQ(p.queue_size, 1);
  EXPECT_EQ(p.segmentation_blend, 1.0);
  EXPECT_EQ(p.downsample, 0);
  EXPECT_EQ(p.cloud_colour, "segment");
  EXPECT_GT(p.max_pair_interval, 0);
  ASSERT_EQ(warnings.size(), 5u);
  EXPECT_EQ(warnings[0], "queue_size 0 messages is outside [1, 10000] messages; using 1");
  auto mentions = [&](const std::string& needle) {
    for (const std::string& w : warnings)
      if (w.find(needle) != std::string::npos) return true;
    return false;
  };
  EXPECT_TRUE(mentions("segmentation_blend 1.5 is outside [0, 1]; using 1"));
  EXPECT_TRUE(mentions("max_pair_interval -1 s is outside"));
  EXPECT_TRUE(mentions("downsample 3 is not 0 (automatic) or a power of two; using 0"));
  EXPECT_TRUE(mentions("cloud_colour 'rainbow'"));

  mc_flow_ros::NodeParameters odometry;
  odometry.publish_odom_tf = true;
  odometry.prior_frame = odometry.odom_frame;
  const std::vector<std::string> odometry_warnings = odometry.sanitise();
  ASSERT_EQ(odometry_warnings.size(), 2u);
  EXPECT_NE(odometry_warnings[0].find("set base_frame"), std::string::npos);
  EXPECT_NE(odometry_warnings[1].find("prior_frame 'odom' is the odom_frame this node broadcasts"), std::string::npos);
}

TEST(NodeParameters, TheStartupDescriptionNamesEveryParameterWithItsUnit) {
  const std::string d = mc_flow_ros::NodeParameters().describe();
  for (const mc_flow_ros::NodeParameterInfo& row : mc_flow_ros::NodeParameters::table())
    EXPECT_NE(d.find(row.name + "="), std::string::npos) << row.name;
  EXPECT_NE(d.find("max_stamp_difference=0.02 s"), std::string::npos) << d;
  EXPECT_NE(d.find("base_frame=''"), std::string::npos) << d;
}

TEST(NodeParameters, TheLaunchFileSetsNoUnknownNodeParameter) {
  const std::string text = launchText();
  // The nodelet's <param> lines (inside the MCFlowNodelet node) name only known parameters.
  const std::size_t node = text.find("load mc_flow/MCFlowNodelet");
  ASSERT_NE(node, std::string::npos);
  const std::string body = text.substr(node, text.find("</node>", node) - node);
  const std::regex param("<param name=\"([^\"]+)\"");
  for (auto it = std::sregex_iterator(body.begin(), body.end(), param); it != std::sregex_iterator(); ++it) {
    const std::string name = (*it)[1].str();
    if (name == "image_transport") continue;  // image_transport's own parameter
    bool known = false;
    for (const auto& [n, v] : mc_flow_ros::NodeParameters::defaults()) known = known || n == name;
    EXPECT_TRUE(known) << "the launch file sets '" << name << "', which the nodelet does not read";
  }
}

}  // namespace
