/**
 * @file config.h
 * @brief Every solver parameter, with its unit, default and range in one place (config_fields.def).
 *
 * The CLI flags, the JSON config file and the ROS dynamic_reconfigure parameters all map onto this
 * struct; none of them repeats a default or a range. `validate()` throws mc_flow::ConfigError naming the field.
 */
#pragma once

#include <string>
#include <vector>

namespace mc_flow {

enum class Regularizer { Quadratic, TotalVariation };
enum class Backend { Auto, Cpu, Cuda };

std::string toString(Regularizer r);
std::string toString(Backend b);
/// @brief Parses "quad"/"quadratic"/"tv"; throws ConfigError naming the text otherwise.
Regularizer parseRegularizer(const std::string& s);
/// @brief Parses "auto"/"cpu"/"cuda"; throws ConfigError naming the text otherwise.
Backend parseBackend(const std::string& s);

/// @brief Every solver parameter. The members, their defaults, units, ranges and descriptions are listed once,
/// in config_fields.def (the table that validate(), set(), fields() and cfg/McFlow.cfg are generated from).
struct Config {
#define MCFLOW_SECTION(title)
#define MCFLOW_PARAM(type, name, default_value, min, max, unit, description) type name = default_value;
#include "mc_flow/core/config_fields.def"
#undef MCFLOW_PARAM
#undef MCFLOW_SECTION

  /// @brief Throws ConfigError naming the first field outside its table range [min, max], or max_depth <= min_depth.
  void validate() const;
  /// @brief The regulariser weight for the selected regulariser.
  double lambda() const { return regularizer == Regularizer::Quadratic ? lambda_quadratic : lambda_tv; }
  /// @brief Sets a field by name from text (JSON/YAML keys and CLI use this); throws ConfigError on an
  /// unknown name or an unparsable value.
  void set(const std::string& name, const std::string& value);
  /// @brief Every field as (name, value-as-text), in declaration order.
  std::vector<std::pair<std::string, std::string>> fields() const;
};

/// @brief One row of config_fields.def; the values as the text that Config::set() parses.
struct ConfigFieldInfo {
  std::string name;
  std::string type;  ///< C++ type: double, int, unsigned, bool, Regularizer, Backend
  std::string default_text;
  std::string min_text;  ///< inclusive; for an enum its first enumerator, for a bool false
  std::string max_text;  ///< inclusive; for an enum its last enumerator, for a bool true
  std::string unit;      ///< "1": dimensionless; "-": not a quantity (flag, choice)
  std::string description;
};

/// @brief The parameter table, in the order of Config::fields().
const std::vector<ConfigFieldInfo>& configFieldTable();

}  // namespace mc_flow
