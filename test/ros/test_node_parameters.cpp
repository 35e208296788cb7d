// Every node parameter appears once in launch/mc_flow.launch, as an argument whose default is the nodelet's
// (include/mc_flow/ros/node_parameters.h) and as a parameter set from that argument.
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
    EXPECT_TRUE(sameDefault(m[1].str(), value)) << "launch default '" << m[1].str() << "', nodelet default '" << value
                                                << "'";
    EXPECT_EQ(count(text, "<arg name=\"" + name + "\""), 1);
    EXPECT_EQ(count(text, "<param name=\"" + name + "\""), 1);
  }
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
