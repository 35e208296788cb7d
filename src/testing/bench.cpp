#include "mc_flow/testing/bench.h"

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <sstream>

namespace mc_flow {

CommandLine::CommandLine(std::string tool, std::vector<CommandLineOption> options)
    : tool_(std::move(tool)), options_(std::move(options)) {
  options_.push_back({"set", true, "name=value: sets one Config field (config_fields.def); may be repeated"});
  options_.push_back({"help", false, "this help"});
}

const CommandLineOption* CommandLine::find(const std::string& name) const {
  for (const CommandLineOption& o : options_)
    if (o.name == name) return &o;
  return nullptr;
}

void CommandLine::parse(int argc, const char* const* argv) {
  given_.clear();
  for (int i = 1; i < argc; ++i) {
    const std::string token = argv[i];
    if (token == "-h") {
      given_.emplace_back("help", "");
      continue;
    }
    if (token.rfind("--", 0) != 0) throw CommandLineError("unexpected argument '" + token + "'");
    std::string name = token.substr(2), value;
    const std::size_t eq = name.find('=');
    const bool inline_value = eq != std::string::npos;
    if (inline_value) {
      value = name.substr(eq + 1);
      name.resize(eq);
    }
    const CommandLineOption* option = find(name);
    if (!option) throw CommandLineError("unknown option '--" + name + "'");
    if (!option->takes_value && inline_value) throw CommandLineError("option --" + name + " takes no value");
    if (option->takes_value && !inline_value) {
      if (i + 1 >= argc) throw CommandLineError("option --" + name + " needs a value");
      value = argv[++i];
    }
    if (name != "set" && has(name)) throw CommandLineError("option --" + name + " given twice");
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

int CommandLine::integer(const std::string& name, int fallback, int min, int max) const {
  if (!has(name)) return fallback;
  const std::string t = text(name, "");
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(t.c_str(), &end, 10);
  if (t.empty() || *end != '\0' || errno == ERANGE || v < min || v > max)
    throw CommandLineError("--" + name + " '" + t + "': expected an integer in [" + std::to_string(min) + ", " +
                           std::to_string(max) + "]");
  return int(v);
}

std::vector<std::string> CommandLine::list(const std::string& name, const std::string& fallback) const {
  std::vector<std::string> items;
  std::stringstream stream(text(name, fallback));
  std::string item;
  while (std::getline(stream, item, ','))
    if (!item.empty()) items.push_back(item);
  return items;
}

void CommandLine::applySettings(Config& config) const {
  for (const auto& [name, assignment] : given_) {
    if (name != "set") continue;
    const std::size_t eq = assignment.find('=');
    if (eq == std::string::npos) throw CommandLineError("--set expects name=value, got '" + assignment + "'");
    config.set(assignment.substr(0, eq), assignment.substr(eq + 1));
  }
}

std::string CommandLine::usage() const {
  std::string out = "usage: " + tool_;
  for (const CommandLineOption& o : options_) out += " [--" + o.name + (o.takes_value ? " VALUE]" : "]");
  out += "\n";
  for (const CommandLineOption& o : options_) {
    const std::string left = "  --" + o.name + (o.takes_value ? " VALUE" : "");
    out += left + std::string(left.size() < 26 ? 26 - left.size() : 1, ' ') + o.help + "\n";
  }
  return out;
}

std::vector<Regularizer> regularizerChoice(const std::string& text) {
  if (text == "both") return {Regularizer::Quadratic, Regularizer::TotalVariation};
  return {parseRegularizer(text)};
}

}  // namespace mc_flow
