/**
 * @file config_file.h
 * @brief Solver configuration files: a flat JSON object or flat YAML mapping whose keys are Config member
 * names, applied through Config::set. Both forms are read with yaml-cpp (YAML 1.2 is a superset of JSON).
 */
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "mc_flow/core/config.h"

namespace mc_flow {
namespace io {

/// @brief (key, value-as-text) pairs of a flat JSON object ("{...}") or flat YAML mapping ("key: value").
/// Throws ConfigError naming `what` and the line for syntax errors, nested or missing values and repeated keys.
std::vector<std::pair<std::string, std::string>> parseFlatKeyValues(const std::string& text, const std::string& what);

/// @brief Reads `path` and applies every key with Config::set; errors name the file and the key.
void applyConfigFile(const std::string& path, Config& config);

}  // namespace io
}  // namespace mc_flow
