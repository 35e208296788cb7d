/**
 * @file bench.h
 * @brief What the benchmark tools share: their command line (one parser). The median of timings they print is
 * mc_flow::median (mc_flow/eval/metrics.h, shared with `mcflow bench-real`).
 *
 * Core only (no OpenCV), like the tools that use it, so that it builds on the GPU machine. Benchmark harness:
 * library mc_flow_testing, linked by the benchmarks and the tests only, not installed.
 */
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/eval/metrics.h"

namespace mc_flow {

/// @brief A command line a tool cannot use: an unknown option, a missing or malformed value. Tools exit with 2.
struct CommandLineError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// @brief One option of a benchmark tool: `--name VALUE` (or `--name=VALUE`) when it takes a value, else a flag.
struct CommandLineOption {
  std::string name;
  bool takes_value = true;
  std::string help;
};

/// @brief The command line of a benchmark tool. `--set name=value` (repeatable, applied to a Config in order)
/// and `--help` are always understood; every other option is declared. An option given twice, a value after
/// a flag, an unknown option or a missing value throws CommandLineError naming it.
class CommandLine {
 public:
  CommandLine(std::string tool, std::vector<CommandLineOption> options);

  void parse(int argc, const char* const* argv);

  bool helpRequested() const { return has("help"); }
  /// @brief True when the flag or the option was given.
  bool has(const std::string& name) const;
  /// @brief The option's text, or `fallback` when it was not given.
  std::string text(const std::string& name, const std::string& fallback) const;
  /// @brief The option as an integer in [min, max], or `fallback`; throws CommandLineError naming the option.
  int integer(const std::string& name, int fallback, int min, int max) const;
  /// @brief The option's comma-separated items (empty items dropped), or those of `fallback`.
  std::vector<std::string> list(const std::string& name, const std::string& fallback) const;
  /// @brief Applies every `--set name=value` in order (Config::set: ConfigError on an unknown name or bad value).
  void applySettings(Config& config) const;

  /// @brief "usage: TOOL [--name VALUE] ...", one line per option with its help.
  std::string usage() const;

 private:
  const CommandLineOption* find(const std::string& name) const;

  std::string tool_;
  std::vector<CommandLineOption> options_;
  std::vector<std::pair<std::string, std::string>> given_;  // (name, value) in command-line order
};

/// @brief "both" (quadratic, then TV), or one regulariser by Config's names; throws ConfigError otherwise.
std::vector<Regularizer> regularizerChoice(const std::string& text);

}  // namespace mc_flow
