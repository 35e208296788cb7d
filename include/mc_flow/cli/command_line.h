/**
 * @file command_line.h
 * @brief The command line of every mc_flow executable: the `mcflow` tool (one CommandLine per subcommand),
 * `make_synthetic_bag` and the benchmarks.
 *
 * Library mc_flow_cli: shipped, and free of ROS and OpenCV, so that the core-only benchmark that runs on the GPU
 * machine uses it too. Tools exit with 2 on a CommandLineError, printing its message and their usage.
 */
#pragma once

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mc_flow/core/config.h"

namespace mc_flow {

/// @brief A command line a tool cannot use: an unknown option, a missing or malformed value, a missing required
/// option. The message names the option and the value. Tools exit with 2.
struct CommandLineError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// @brief One option: `--name VALUE` (or `--name=VALUE`) when it takes a value, else a flag. Only a repeatable
/// option may be given more than once (its values are kept in order).
struct CommandLineOption {
  std::string name;  ///< without the leading "--"
  bool takes_value = true;
  std::string help;
  bool repeatable = false;
};

/// @brief Whether a CommandLine adds the standard `--set name=value` (repeatable: one Config field each) to the
/// options it declares.
enum class ConfigSettings { Accepted, Refused };

/// @brief A command line: declared options, `--help` (and `-h`) always, `--set` unless refused, and optionally
/// named positional arguments. An unknown option, a value after a flag, a missing value, a non-repeatable option
/// given twice or a surplus argument throws CommandLineError naming it.
class CommandLine {
 public:
  /// @param tool       the name usage() and the messages give, e.g. "mcflow run"
  /// @param options    the tool's options, in the order usage() lists them; an option named "set" or "help" in it
  ///                   replaces the standard one (e.g. to word its help for the tool)
  /// @param positional names of the positional arguments, in order (e.g. {"OUTPUT.bag"}); all optional to the
  ///                   parser (positionalText says whether one was given)
  CommandLine(std::string tool, std::vector<CommandLineOption> options,
              ConfigSettings settings = ConfigSettings::Accepted, std::vector<std::string> positional = {});

  /// @brief Parses argv[1..argc-1] (argv[0] is the program, or the subcommand's name). Forgets an earlier parse.
  void parse(int argc, const char* const* argv);

  bool helpRequested() const { return has("help"); }
  /// @brief True when the flag or the option was given.
  bool has(const std::string& name) const;
  /// @brief The option's text (its first value), or `fallback` when it was not given.
  std::string text(const std::string& name, const std::string& fallback) const;
  /// @brief The option's text; CommandLineError "missing required option --NAME" when it was not given.
  std::string required(const std::string& name) const;
  /// @brief Every value of the option, in command-line order (a repeatable option's).
  std::vector<std::string> values(const std::string& name) const;
  /// @brief The option as an integer in [min, max], or `fallback`; throws CommandLineError naming the option.
  int integer(const std::string& name, int fallback, int min, int max) const;
  /// @brief The option as any int (for values whose range a Config or the solver checks), or `fallback`.
  int integer(const std::string& name, int fallback) const;
  /// @brief The option as a finite number, or `fallback`; throws CommandLineError naming the option and value.
  double number(const std::string& name, double fallback) const;
  /// @brief The option's comma-separated items (empty items dropped), or those of `fallback`.
  std::vector<std::string> list(const std::string& name, const std::string& fallback) const;
  /// @brief The i-th positional argument, or `fallback` when fewer were given.
  std::string positionalText(std::size_t i, const std::string& fallback) const;
  /// @brief Applies every `--set name=value` in order (applyConfigSetting).
  void applySettings(Config& config) const;

  /// @brief "usage: TOOL [POSITIONAL] [--name VALUE] ..." and then optionsHelp().
  std::string usage() const;
  /// @brief One line per option: "  --name VALUE" and its help, the help starting at column 26.
  std::string optionsHelp() const;

 private:
  const CommandLineOption* find(const std::string& name) const;

  std::string tool_;
  std::vector<CommandLineOption> options_;
  std::vector<std::string> positional_names_, positional_;
  std::vector<std::pair<std::string, std::string>> given_;  // (name, value) in command-line order
};

/// @brief Applies one `name=value` assignment (the text of a `--set`; spaces around both parts ignored) with
/// Config::set. CommandLineError without a name or '='; ConfigError, naming the assignment, on an unknown name or a
/// bad value.
void applyConfigSetting(const std::string& assignment, Config& config);

}  // namespace mc_flow
