// The benchmark tools' shared command line and median (mc_flow/testing/bench.h).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "mc_flow/core/error.h"
#include "mc_flow/testing/bench.h"

namespace mc_flow {
namespace {

CommandLine benchCommandLine() {
  return CommandLine("tool", {{"width", true, "w"}, {"noise", false, "flag"}, {"sizes", true, "list"}});
}

void parse(CommandLine& cli, std::vector<const char*> args) {
  args.insert(args.begin(), "tool");
  cli.parse(int(args.size()), args.data());
}

TEST(BenchCommandLine, ReadsValuesFlagsListsAndSettingsInOrder) {
  CommandLine cli = benchCommandLine();
  parse(cli, {"--width", "64", "--noise", "--sizes=8x6,,16x12", "--set", "alpha=3", "--set=alpha=4.5"});
  EXPECT_EQ(cli.integer("width", 320, 16, 8192), 64);
  EXPECT_TRUE(cli.has("noise"));
  EXPECT_FALSE(cli.helpRequested());
  EXPECT_EQ(cli.list("sizes", ""), (std::vector<std::string>{"8x6", "16x12"}));
  Config config;
  cli.applySettings(config);
  EXPECT_EQ(config.alpha, 4.5) << "the later --set wins";
}

TEST(BenchCommandLine, FallsBackWhenAnOptionIsAbsent) {
  CommandLine cli = benchCommandLine();
  parse(cli, {});
  EXPECT_EQ(cli.integer("width", 320, 16, 8192), 320);
  EXPECT_EQ(cli.text("sizes", "a,b"), "a,b");
  EXPECT_EQ(cli.list("sizes", "a,b").size(), 2u);
  EXPECT_FALSE(cli.has("noise"));
}

TEST(BenchCommandLine, RejectsWhatItCannotUseNamingIt) {
  auto expectError = [](std::vector<const char*> args, const std::string& needle) {
    CommandLine cli = benchCommandLine();
    try {
      parse(cli, args);
      cli.integer("width", 320, 16, 8192);
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const CommandLineError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expectError({"--depth", "3"}, "--depth");
  expectError({"--width"}, "--width");
  expectError({"--width", "64", "--width", "65"}, "twice");
  expectError({"--noise=1"}, "--noise");
  expectError({"stray"}, "stray");
  expectError({"--width", "64px"}, "64px");
  expectError({"--width", "8"}, "[16, 8192]");

  CommandLine cli = benchCommandLine();
  parse(cli, {"--set", "alpha"});
  Config config;
  EXPECT_THROW(cli.applySettings(config), CommandLineError);
  parse(cli, {"--set", "no_such_field=1"});
  EXPECT_THROW(cli.applySettings(config), ConfigError);
}

TEST(BenchCommandLine, UsageListsEveryOptionWithItsHelp) {
  const std::string usage = benchCommandLine().usage();
  for (const char* text : {"--width VALUE", "--noise", "--set VALUE", "--help", "flag"})
    EXPECT_NE(usage.find(text), std::string::npos) << text << " missing from\n" << usage;
}

TEST(BenchMedian, MiddleElementOfTheSortedValues) {
  EXPECT_EQ(median({}), 0.0);
  EXPECT_EQ(median({3.0}), 3.0);
  EXPECT_EQ(median({5.0, 1.0, 3.0}), 3.0);
  EXPECT_EQ(median({4.0, 1.0, 3.0, 2.0}), 3.0) << "even count: the upper of the two middle values";
}

}  // namespace
}  // namespace mc_flow
