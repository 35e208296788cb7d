/**
 * @file reconfigure.h
 * @brief The one bridge between dynamic_reconfigure and the core: McFlowConfig -> mc_flow::Config.
 *
 * cfg/McFlow.cfg generates one parameter per field of mc_flow::Config (same name, default read from
 * config.h), so the mapping is generic: every parameter is handed to Config::set() by name.
 */
#pragma once

#include <string>
#include <vector>

#include "mc_flow/McFlowConfig.h"
#include "mc_flow/core/config.h"

namespace mc_flow_ros {

/// @brief Maps every dynamic_reconfigure parameter onto the core Config (by name, via Config::set) and
/// validates it. Throws mc_flow::ConfigError naming the parameter when a value is rejected or when a
/// parameter has no Config field of its name.
mc_flow::Config toCoreConfig(const mc_flow::McFlowConfig& parameters);

/// @brief (name, value-as-text) of every dynamic_reconfigure parameter, in generation order.
std::vector<std::pair<std::string, std::string>> parameterTexts(const mc_flow::McFlowConfig& parameters);

}  // namespace mc_flow_ros
