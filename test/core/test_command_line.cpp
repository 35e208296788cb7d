// The command line of every mc_flow executable (mc_flow/cli/command_line.h): mcflow's subcommands,
// make_synthetic_bag and the benchmarks parse with it.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "mc_flow/cli/command_line.h"
#include "mc_flow/core/error.h"

namespace mc_flow {
namespace {

CommandLine toolCommandLine(ConfigSettings settings = ConfigSettings::Accepted) {
  return CommandLine("tool", {{"width", true, "w"}, {"noise", false, "flag"}, {"sizes", true, "list"}}, settings);
}

void parse(CommandLine& cli, std::vector<const char*> args) {
  args.insert(args.begin(), "tool");
  cli.parse(int(args.size()), args.data());
}

// Parses `args` and reads --width; expects a CommandLineError whose message contains every one of `needles`.
void expectError(CommandLine cli, std::vector<const char*> args, const std::vector<std::string>& needles) {
  try {
    parse(cli, args);
    cli.integer("width", 320, 16, 8192);
    ADD_FAILURE() << "accepted: " << needles.front();
  } catch (const CommandLineError& e) {
    for (const std::string& needle : needles)
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << needle << " not in: " << e.what();
  }
}

TEST(CommandLine, ReadsValuesFlagsListsAndSettingsInOrder) {
  CommandLine cli = toolCommandLine();
  parse(cli, {"--width", "64", "--noise", "--sizes=8x6,,16x12", "--set", "alpha=3", "--set=alpha=4.5"});
  EXPECT_EQ(cli.integer("width", 320, 16, 8192), 64);
  EXPECT_TRUE(cli.has("noise"));
  EXPECT_FALSE(cli.helpRequested());
  EXPECT_EQ(cli.list("sizes", ""), (std::vector<std::string>{"8x6", "16x12"}));
  EXPECT_EQ(cli.values("set"), (std::vector<std::string>{"alpha=3", "alpha=4.5"}));
  Config config;
  cli.applySettings(config);
  EXPECT_EQ(config.alpha, 4.5) << "the later --set wins";
}

TEST(CommandLine, FallsBackWhenAnOptionIsAbsent) {
  CommandLine cli = toolCommandLine();
  parse(cli, {});
  EXPECT_EQ(cli.integer("width", 320, 16, 8192), 320);
  EXPECT_EQ(cli.integer("width", -1), -1);
  EXPECT_EQ(cli.number("width", 2.5), 2.5);
  EXPECT_EQ(cli.text("sizes", "a,b"), "a,b");
  EXPECT_EQ(cli.list("sizes", "a,b").size(), 2u);
  EXPECT_TRUE(cli.values("set").empty());
  EXPECT_FALSE(cli.has("noise"));
  EXPECT_EQ(cli.positionalText(0, "none"), "none");
}

TEST(CommandLine, ANewParseForgetsTheLastOne) {
  CommandLine cli = toolCommandLine();
  parse(cli, {"--width", "64"});
  parse(cli, {"--width", "65"});
  EXPECT_EQ(cli.integer("width", 320, 16, 8192), 65);
}

TEST(CommandLine, RejectsWhatItCannotUseNamingTheOptionAndValue) {
  expectError(toolCommandLine(), {"--depth", "3"}, {"unknown option", "--depth"});
  expectError(toolCommandLine(), {"--width"}, {"--width", "needs a value"});
  expectError(toolCommandLine(), {"--width", "64", "--width", "65"}, {"--width", "given twice"});
  expectError(toolCommandLine(), {"--noise", "--noise"}, {"--noise", "given twice"});
  expectError(toolCommandLine(), {"--noise=1"}, {"--noise", "takes no value", "'1'"});
  expectError(toolCommandLine(), {"stray"}, {"unexpected argument", "stray"});
  expectError(toolCommandLine(), {"-3"}, {"unexpected argument", "-3"});
  expectError(toolCommandLine(), {"--width", "64px"}, {"--width", "64px"});
  expectError(toolCommandLine(), {"--width", ""}, {"--width", "expected an integer"});
  expectError(toolCommandLine(), {"--width", "8"}, {"--width", "'8'", "[16, 8192]"});
  expectError(toolCommandLine(), {"--width", "99999999999"}, {"--width", "99999999999"});
}

TEST(CommandLine, NumbersAndIntegersNameTheOptionAndValue) {
  CommandLine cli = toolCommandLine();
  parse(cli, {"--width", "-0.5e1"});
  EXPECT_EQ(cli.number("width", 0), -5.0) << "a value may look like an option's dash";
  parse(cli, {"--width=nan"});
  try {
    cli.number("width", 0);
    ADD_FAILURE() << "accepted nan";
  } catch (const CommandLineError& e) {
    EXPECT_EQ(std::string(e.what()), "--width 'nan': expected a number");
  }
  parse(cli, {"--width", "1.5"});
  try {
    cli.integer("width", 0);
    ADD_FAILURE() << "accepted 1.5";
  } catch (const CommandLineError& e) {
    EXPECT_EQ(std::string(e.what()), "--width '1.5': expected an integer") << "no range when any int will do";
  }
}

TEST(CommandLine, RequiredOptionsNameWhatIsMissing) {
  CommandLine cli = toolCommandLine();
  parse(cli, {"--sizes", "8x6"});
  EXPECT_EQ(cli.required("sizes"), "8x6");
  try {
    cli.required("width");
    ADD_FAILURE() << "no error for a missing --width";
  } catch (const CommandLineError& e) {
    EXPECT_EQ(std::string(e.what()), "missing required option --width");
  }
}

TEST(CommandLine, PositionalArgumentsUpToTheDeclaredNumber) {
  CommandLine cli("tool", {{"frames", true, "n"}}, ConfigSettings::Refused, {"OUTPUT"});
  parse(cli, {"--frames", "3", "out.bag"});
  EXPECT_EQ(cli.positionalText(0, ""), "out.bag");
  EXPECT_EQ(cli.integer("frames", 0, 2, 100), 3);
  expectError(cli, {"a.bag", "b.bag"}, {"unexpected argument", "b.bag"});
  EXPECT_NE(cli.usage().find("usage: tool OUTPUT [--frames VALUE] [--help]"), std::string::npos) << cli.usage();
}

TEST(CommandLine, SettingsCanBeRefusedOrWordedByTheTool) {
  expectError(toolCommandLine(ConfigSettings::Refused), {"--set", "alpha=2"}, {"unknown option", "--set"});
  CommandLine own("tool", {{"set", true, "overrides --config", true}, {"help", false, "this tool's help"}});
  const std::string usage = own.usage();
  EXPECT_NE(usage.find("overrides --config"), std::string::npos) << usage;
  EXPECT_EQ(usage.find("config_fields.def"), std::string::npos) << "the standard --set was added too:\n" << usage;
  EXPECT_EQ(usage.find("this help"), std::string::npos) << "the standard --help was added too:\n" << usage;
}

TEST(CommandLine, HelpLongAndShort) {
  for (const char* help : {"--help", "-h"}) {
    CommandLine cli = toolCommandLine();
    parse(cli, {"--width", "64", help});
    EXPECT_TRUE(cli.helpRequested()) << help;
  }
  expectError(toolCommandLine(), {"--help=yes"}, {"--help", "takes no value"});
}

TEST(CommandLine, UsageListsEveryOptionWithItsHelpInOneColumn) {
  const std::string usage = toolCommandLine().usage();
  for (const char* text : {"usage: tool [--width VALUE]", "--noise", "--set VALUE", "--help", "flag"})
    EXPECT_NE(usage.find(text), std::string::npos) << text << " missing from\n" << usage;
  // The help starts at column 26 (mcflow's subcommands printed it there before they used this parser).
  EXPECT_NE(usage.find("\n  --width VALUE" + std::string(11, ' ') + "w\n"), std::string::npos) << usage;
  EXPECT_NE(toolCommandLine().optionsHelp().find("  --noise" + std::string(17, ' ') + "flag\n"), std::string::npos);
}

TEST(ConfigSetting, AppliesNameEqualsValueAndNamesWhatItCannotUse) {
  Config config;
  applyConfigSetting(" alpha = 0.75 ", config);
  EXPECT_EQ(config.alpha, 0.75) << "spaces around the name and the value are ignored";
  EXPECT_THROW(applyConfigSetting("alpha", config), CommandLineError);
  EXPECT_THROW(applyConfigSetting("=3", config), CommandLineError);
  try {
    applyConfigSetting("no_such_field=1", config);
    ADD_FAILURE() << "accepted an unknown field";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("--set 'no_such_field=1'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(applyConfigSetting("alpha=fast", config), ConfigError);
}

}  // namespace
}  // namespace mc_flow
