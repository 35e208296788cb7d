// dynamic_reconfigure <-> mc_flow::Config: the .cfg's defaults are the core's (no drift possible).
#include <gtest/gtest.h>

#include <map>
#include <set>
#include <string>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/ros/reconfigure.h"

TEST(Reconfigure, DefaultsEqualCoreConfigDefaults) {
  const mc_flow::Config mapped = mc_flow_ros::toCoreConfig(mc_flow::McFlowConfig::__getDefault__());
  const auto expected = mc_flow::Config().fields();
  const auto actual = mapped.fields();
  ASSERT_EQ(actual.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(actual[i].first, expected[i].first);
    EXPECT_EQ(actual[i].second, expected[i].second) << "default of " << expected[i].first << " differs";
  }
}

TEST(Reconfigure, EveryCoreFieldIsAParameterAndViceVersa) {
  std::set<std::string> core, parameters;
  for (const auto& field : mc_flow::Config().fields()) core.insert(field.first);
  for (const auto& p : mc_flow_ros::parameterTexts(mc_flow::McFlowConfig::__getDefault__())) parameters.insert(p.first);
  EXPECT_EQ(core, parameters);
}

TEST(Reconfigure, DefaultsLieInsideTheOfferedRanges) {
  const auto& min = mc_flow::McFlowConfig::__getMin__();
  const auto& max = mc_flow::McFlowConfig::__getMax__();
  const auto defaults = mc_flow_ros::parameterTexts(mc_flow::McFlowConfig::__getDefault__());
  const auto lows = mc_flow_ros::parameterTexts(min);
  const auto highs = mc_flow_ros::parameterTexts(max);
  for (std::size_t i = 0; i < defaults.size(); ++i) {
    if (lows[i].second.empty() || lows[i].second == "false" || lows[i].second == "true") continue;  // str, bool
    char* end = nullptr;
    const double value = std::strtod(defaults[i].second.c_str(), &end);
    if (*end != '\0') continue;
    EXPECT_LE(std::strtod(lows[i].second.c_str(), nullptr), value) << defaults[i].first;
    EXPECT_GE(std::strtod(highs[i].second.c_str(), nullptr), value) << defaults[i].first;
  }
}

// The GUI must never offer a value that the core rejects: each offered bound, with every other parameter at its
// default, passes Config::validate(), and the offered range is the core table's.
TEST(Reconfigure, EveryOfferedBoundIsAcceptedByTheCore) {
  const auto defaults = mc_flow_ros::parameterTexts(mc_flow::McFlowConfig::__getDefault__());
  const auto lows = mc_flow_ros::parameterTexts(mc_flow::McFlowConfig::__getMin__());
  const auto highs = mc_flow_ros::parameterTexts(mc_flow::McFlowConfig::__getMax__());
  std::map<std::string, mc_flow::ConfigFieldInfo> table;
  for (const auto& field : mc_flow::configFieldTable()) table[field.name] = field;
  ASSERT_EQ(table.size(), defaults.size());
  for (std::size_t i = 0; i < defaults.size(); ++i) {
    const std::string& name = defaults[i].first;
    ASSERT_EQ(table.count(name), 1u) << name;
    const mc_flow::ConfigFieldInfo& row = table[name];
    if (row.type != "double" && row.type != "int" && row.type != "unsigned") continue;
    EXPECT_DOUBLE_EQ(std::stod(lows[i].second), std::stod(row.min_text)) << name;
    EXPECT_DOUBLE_EQ(std::stod(highs[i].second), std::stod(row.max_text)) << name;
    for (const std::string& bound : {lows[i].second, highs[i].second}) {
      mc_flow::Config config;
      config.set(name, bound);
      EXPECT_NO_THROW(config.validate()) << name << " = " << bound << " is offered but rejected";
    }
  }
}

TEST(Reconfigure, ChangedValuesReachTheCoreConfig) {
  mc_flow::McFlowConfig parameters = mc_flow::McFlowConfig::__getDefault__();
  parameters.alpha = 3.25;
  parameters.initial_labels = 12;
  parameters.regularizer = "tv";
  parameters.backend = "cpu";
  parameters.detect_occlusions = !mc_flow::Config().detect_occlusions;
  parameters.label_cost = 0.1234567890123;
  const mc_flow::Config config = mc_flow_ros::toCoreConfig(parameters);
  EXPECT_DOUBLE_EQ(config.alpha, 3.25);
  EXPECT_EQ(config.initial_labels, 12);
  EXPECT_EQ(config.regularizer, mc_flow::Regularizer::TotalVariation);
  EXPECT_EQ(config.backend, mc_flow::Backend::Cpu);
  EXPECT_EQ(config.detect_occlusions, !mc_flow::Config().detect_occlusions);
  EXPECT_EQ(config.label_cost, 0.1234567890123);  // exact: the text keeps 17 digits
}

TEST(Reconfigure, InvalidValuesAreRejectedNamingTheParameter) {
  mc_flow::McFlowConfig parameters = mc_flow::McFlowConfig::__getDefault__();
  parameters.max_depth = 0.05;  // below min_depth
  try {
    mc_flow_ros::toCoreConfig(parameters);
    FAIL() << "max_depth < min_depth was accepted";
  } catch (const mc_flow::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("max_depth"), std::string::npos) << e.what();
  }
  parameters = mc_flow::McFlowConfig::__getDefault__();
  parameters.regularizer = "l1";
  try {
    mc_flow_ros::toCoreConfig(parameters);
    FAIL() << "regularizer 'l1' was accepted";
  } catch (const mc_flow::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("regularizer"), std::string::npos) << e.what();
  }
}
