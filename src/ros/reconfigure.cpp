#include "mc_flow/ros/reconfigure.h"

#include <cstdio>

#include <boost/any.hpp>

#include "mc_flow/core/error.h"

namespace mc_flow_ros {

namespace {

std::string anyToText(const boost::any& value, const std::string& type) {
  if (type == "bool") return boost::any_cast<bool>(value) ? "true" : "false";
  if (type == "int") return std::to_string(boost::any_cast<int>(value));
  if (type == "double") {
    char buffer[64];  // 17 significant digits: the text parses back to the same double
    std::snprintf(buffer, sizeof(buffer), "%.17g", boost::any_cast<double>(value));
    return buffer;
  }
  return boost::any_cast<std::string>(value);
}

}  // namespace

std::vector<std::pair<std::string, std::string>> parameterTexts(const mc_flow::McFlowConfig& parameters) {
  std::vector<std::pair<std::string, std::string>> texts;
  for (const auto& description : mc_flow::McFlowConfig::__getParamDescriptions__()) {
    boost::any value;
    description->getValue(parameters, value);
    texts.emplace_back(description->name, anyToText(value, description->type));
  }
  return texts;
}

mc_flow::Config toCoreConfig(const mc_flow::McFlowConfig& parameters) {
  mc_flow::Config config;
  for (const auto& [name, text] : parameterTexts(parameters)) {
    try {
      config.set(name, text);
    } catch (const mc_flow::ConfigError& e) {
      throw mc_flow::ConfigError("dynamic_reconfigure parameter '" + name + "' = '" + text + "': " + e.what());
    }
  }
  config.validate();
  return config;
}

}  // namespace mc_flow_ros
