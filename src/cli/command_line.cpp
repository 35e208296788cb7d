#include "mc_flow/cli/command_line.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>

#include "mc_flow/core/error.h"
#include "mc_flow/io/text.h"

namespace mc_flow {

CommandLine::CommandLine(std::string tool, std::vector<CommandLineOption> options, ConfigSettings settings,
                         std::vector<std::string> positional)
    : tool_(std::move(tool)), options_(std::move(options)), positional_names_(std::move(positional)) {
  if (settings == ConfigSettings::Accepted && !find("set"))
    options_.push_back({"set", true, "name=value: sets one Config field (config_fields.def); may be repeated", true});
  if (!find("help")) options_.push_back({"help", false, "this help"});
}

const CommandLineOption* CommandLine::find(const std::string& name) const {
  for (const CommandLineOption& o : options_)
    if (o.name == name) return &o;
  return nullptr;
}

void CommandLine::parse(int argc, const char* const* argv) {
  given_.clear();
  positional_.clear();
  for (int i = 1; i < argc; ++i) {
    const std::string token = argv[i];
    if (token == "-h") {
      given_.emplace_back("help", "");
      continue;
    }
    if (token.rfind("--", 0) != 0) {
      // A lone "-" or a negative number can only be a value, and values follow their option.
      if (token.rfind('-', 0) == 0 || positional_.size() >= positional_names_.size())
        throw CommandLineError("unexpected argument '" + token + "'");
      positional_.push_back(token);
      continue;
    }
    std::string name = token.substr(2), value;
    const std::size_t eq = name.find('=');
    const bool inline_value = eq != std::string::npos;
    if (inline_value) {
      value = name.substr(eq + 1);
      name.resize(eq);
    }
    const CommandLineOption* option = find(name);
    if (!option) throw CommandLineError("unknown option '--" + name + "'");
    if (!option->takes_value && inline_value)
      throw CommandLineError("option --" + name + " takes no value (got '" + value + "')");
    if (option->takes_value && !inline_value) {
      if (i + 1 >= argc) throw CommandLineError("option --" + name + " needs a value");
      value = argv[++i];
    }
    if (!option->repeatable && has(name)) throw CommandLineError("option --" + name + " given twice");
    given_.emplace_back(name, value);
  }
}

bool CommandLine::has(const std::string& name) const {
  return std::any_of(given_.begin(), given_.end(), [&](const auto& g) { return g.first == name; });
}

std::string CommandLine::text(const std::string& name, const std::string& fallback) const {
  for (const auto& [given, value] : given_)
    if (given == name) return value;
  return fallback;
}

std::string CommandLine::required(const std::string& name) const {
  if (!has(name)) throw CommandLineError("missing required option --" + name);
  return text(name, "");
}

std::vector<std::string> CommandLine::values(const std::string& name) const {
  std::vector<std::string> all;
  for (const auto& [given, value] : given_)
    if (given == name) all.push_back(value);
  return all;
}

int CommandLine::integer(const std::string& name, int fallback, int min, int max) const {
  if (!has(name)) return fallback;
  const std::string t = text(name, "");
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(t.c_str(), &end, 10);
  if (t.empty() || *end != '\0' || errno == ERANGE || v < min || v > max) {
    const bool bounded = min != std::numeric_limits<int>::min() || max != std::numeric_limits<int>::max();
    throw CommandLineError("--" + name + " '" + t + "': expected an integer" +
                           (bounded ? " in [" + std::to_string(min) + ", " + std::to_string(max) + "]" : ""));
  }
  return int(v);
}

int CommandLine::integer(const std::string& name, int fallback) const {
  return integer(name, fallback, std::numeric_limits<int>::min(), std::numeric_limits<int>::max());
}

double CommandLine::number(const std::string& name, double fallback) const {
  if (!has(name)) return fallback;
  const std::string t = text(name, "");
  char* end = nullptr;
  const double v = std::strtod(t.c_str(), &end);
  if (t.empty() || *end != '\0' || !std::isfinite(v))
    throw CommandLineError("--" + name + " '" + t + "': expected a number");
  return v;
}

std::vector<std::string> CommandLine::list(const std::string& name, const std::string& fallback) const {
  std::vector<std::string> items;
  std::stringstream stream(text(name, fallback));
  std::string item;
  while (std::getline(stream, item, ','))
    if (!item.empty()) items.push_back(item);
  return items;
}

std::string CommandLine::positionalText(std::size_t i, const std::string& fallback) const {
  return i < positional_.size() ? positional_[i] : fallback;
}

void CommandLine::applySettings(Config& config) const {
  for (const std::string& assignment : values("set")) applyConfigSetting(assignment, config);
}

std::string CommandLine::usage() const {
  std::string out = "usage: " + tool_;
  for (const std::string& p : positional_names_) out += " " + p;
  for (const CommandLineOption& o : options_) out += " [--" + o.name + (o.takes_value ? " VALUE]" : "]");
  return out + "\n" + optionsHelp();
}

std::string CommandLine::optionsHelp() const {
  std::string out;
  for (const CommandLineOption& o : options_) {
    const std::string left = "  --" + o.name + (o.takes_value ? " VALUE" : "");
    out += left + std::string(left.size() < 26 ? 26 - left.size() : 1, ' ') + o.help + "\n";
  }
  return out;
}

void applyConfigSetting(const std::string& assignment, Config& config) {
  const std::size_t eq = assignment.find('=');
  const std::string name = io::trimWhitespace(assignment.substr(0, eq));
  if (eq == std::string::npos || name.empty())
    throw CommandLineError("--set '" + assignment + "': expected name=value");
  try {
    config.set(name, io::trimWhitespace(assignment.substr(eq + 1)));
  } catch (const std::exception& e) {
    throw ConfigError("--set '" + assignment + "': " + e.what());
  }
}

}  // namespace mc_flow
