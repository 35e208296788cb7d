#include "mc_flow/io/config_file.h"

#include <set>

#include <yaml-cpp/yaml.h>

#include "mc_flow/core/error.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"

namespace mc_flow {
namespace io {
namespace {

// yaml-cpp marks count lines from 0; people count from 1.
std::string lineOf(const YAML::Mark& mark) { return "line " + std::to_string(mark.line + 1); }

}  // namespace

std::vector<std::pair<std::string, std::string>> parseFlatKeyValues(const std::string& text, const std::string& what) {
  // YAML 1.2 is a superset of JSON, so one parser reads both forms.
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw ConfigError(what + ", " + lineOf(e.mark) + ", column " + std::to_string(e.mark.column + 1) + ": " + e.msg);
  }
  std::vector<std::pair<std::string, std::string>> out;
  std::set<std::string> seen;
  if (root.IsNull()) return out;  // empty file or only comments
  if (!root.IsMap())
    throw ConfigError(what + ", " + lineOf(root.Mark()) +
                      ": expected a mapping of Config field names to values ('name: value' or {\"name\": value})");
  for (const auto& entry : root) {
    const YAML::Node& key = entry.first;
    const YAML::Node& value = entry.second;
    if (!key.IsScalar()) throw ConfigError(what + ", " + lineOf(key.Mark()) + ": a key must be a plain name");
    const std::string name = key.Scalar();
    const std::string where = what + ", " + lineOf(key.Mark());
    if (value.IsNull()) throw ConfigError(where + ": '" + name + "' has no value");
    if (!value.IsScalar())
      throw ConfigError(where + ": value of '" + name +
                        "' must be a number, string or boolean (nested values are not Config fields)");
    if (!seen.insert(name).second) throw ConfigError(where + ": '" + name + "' is given twice");
    out.emplace_back(name, value.Scalar());
  }
  return out;
}

void applyConfigFile(const std::string& path, Config& config) {
  if (!fileExists(path)) throw ConfigError("config file '" + path + "': file does not exist");
  const std::string what = "config file '" + path + "'";
  for (const auto& [key, value] : parseFlatKeyValues(readTextFile(path), what)) {
    try {
      config.set(key, value);
    } catch (const std::exception& e) {
      throw ConfigError(what + ", key '" + key + "' = '" + value + "': " + e.what());
    }
  }
}

}  // namespace io
}  // namespace mc_flow
