#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"

namespace mc_flow {
namespace {

// Expects validate() to throw a ConfigError whose message names `field`.
template <typename Mutate>
void expectInvalid(const std::string& field, Mutate mutate) {
  Config c;
  mutate(c);
  try {
    c.validate();
    ADD_FAILURE() << field << ": no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << "message '" << e.what() << "' lacks " << field;
  }
}

TEST(Config, BadValuesThrowNamingTheField) {
  expectInvalid("max_depth", [](Config& c) { c.max_depth = 0.05; });  // below min_depth
  expectInvalid("min_depth", [](Config& c) { c.min_depth = 0; });
  expectInvalid("min_depth", [](Config& c) { c.min_depth = std::nan(""); });
  expectInvalid("initial_labels", [](Config& c) { c.initial_labels = 0; });
  expectInvalid("initial_labels", [](Config& c) { c.initial_labels = 65; });
  expectInvalid("outer_iterations", [](Config& c) { c.outer_iterations = 0; });
  expectInvalid("label_iterations", [](Config& c) { c.label_iterations = -3; });
  expectInvalid("cauchy_c_depth", [](Config& c) { c.cauchy_c_depth = -0.01; });
  expectInvalid("cauchy_c_intensity", [](Config& c) { c.cauchy_c_intensity = 0; });
  expectInvalid("lambda_quadratic", [](Config& c) { c.lambda_quadratic = 0; });
  expectInvalid("min_support_fraction", [](Config& c) { c.min_support_fraction = 1.0; });
  expectInvalid("min_label_weight", [](Config& c) { c.min_label_weight = -0.1; });
  expectInvalid("depth_downsample_range", [](Config& c) { c.depth_downsample_range = 0; });
  expectInvalid("threads", [](Config& c) { c.threads = -1; });
  expectInvalid("processing_level", [](Config& c) { c.processing_level = -1; });
}

// ---- the parameter table (config_fields.def) ----

TEST(ConfigTable, ListsEveryFieldOnceWithItsDefault) {
  const auto fields = Config().fields();
  const auto& table = configFieldTable();
  ASSERT_EQ(table.size(), fields.size());
  for (std::size_t i = 0; i < table.size(); ++i) {
    EXPECT_EQ(table[i].name, fields[i].first);
    EXPECT_EQ(table[i].default_text, fields[i].second) << table[i].name;
  }
}

TEST(ConfigTable, EveryFieldHasADescriptionAndAUnit) {
  for (const ConfigFieldInfo& f : configFieldTable()) {
    EXPECT_GE(f.description.size(), 10u) << f.name << ": description '" << f.description << "'";
    EXPECT_FALSE(f.unit.empty()) << f.name;
    const bool quantity = f.type == "double" || f.type == "int" || f.type == "unsigned";
    EXPECT_EQ(f.unit == "-", !quantity) << f.name << ": '-' is the unit of flags and choices only";
    EXPECT_EQ(f.description.find('"'), std::string::npos) << f.name << ": the .cfg reads descriptions as plain text";
  }
}

// The GUI offers exactly [min, max] (cfg/McFlow.cfg reads the same table): each bound, with every other field
// at its default, must pass validate().
TEST(ConfigTable, ValidateAcceptsTheDefaultsAndEveryBound) {
  EXPECT_NO_THROW(Config().validate());
  for (const ConfigFieldInfo& f : configFieldTable()) {
    for (const std::string& bound : {f.min_text, f.max_text}) {
      Config c;
      c.set(f.name, bound);
      EXPECT_NO_THROW(c.validate()) << f.name << " = " << bound;
    }
  }
}

// Just outside a bound: the next representable value (doubles) or the next integer, where the type can hold it.
TEST(ConfigTable, ValidateRejectsJustOutsideEveryBound) {
  int checked = 0;
  for (const ConfigFieldInfo& f : configFieldTable()) {
    std::vector<std::string> outside;
    if (f.type == "double") {
      const double lo = std::stod(f.min_text), hi = std::stod(f.max_text);
      for (double v : {std::nextafter(lo, -std::numeric_limits<double>::infinity()),
                       std::nextafter(hi, std::numeric_limits<double>::infinity())}) {
        // Beside 0 the next double is subnormal, which the parser refuses (ERANGE): take the smallest normal one.
        if (std::abs(v) < std::numeric_limits<double>::min()) v = std::copysign(std::numeric_limits<double>::min(), v);
        char text[64];
        std::snprintf(text, sizeof(text), "%.17g", v);
        outside.push_back(text);
      }
    } else if (f.type == "int" || f.type == "unsigned") {
      const long long lo = std::stoll(f.min_text), hi = std::stoll(f.max_text);
      if (f.type == "int" || lo > 0) outside.push_back(std::to_string(lo - 1));
      outside.push_back(std::to_string(hi + 1));
    } else {
      continue;  // bool, enum: set() accepts only the values that exist
    }
    for (const std::string& text : outside) {
      Config c;
      c.set(f.name, text);
      try {
        c.validate();
        ADD_FAILURE() << f.name << " = " << text << " accepted; table range [" << f.min_text << ", " << f.max_text
                      << "]";
      } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find(f.name), std::string::npos) << e.what();
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 80);
}

TEST(Config, MessageNamesTheValue) {
  Config c;
  c.initial_labels = 99;
  try {
    c.validate();
    FAIL() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("99"), std::string::npos) << e.what();
  }
}

TEST(Config, FieldsRoundTripThroughSet) {
  const Config defaults;
  const auto fields = defaults.fields();
  ASSERT_FALSE(fields.empty());
  std::set<std::string> names;
  for (const auto& [name, value] : fields) {
    EXPECT_TRUE(names.insert(name).second) << "field listed twice: " << name;
    Config c;
    EXPECT_NO_THROW(c.set(name, value)) << name << " = " << value;
    EXPECT_EQ(c.fields(), fields) << "set(" << name << ", " << value << ") changed the config";
  }
}

TEST(Config, EachNameSetsItsOwnField) {
  // Setting one field to another value changes that field's text and no other (catches a table entry
  // bound to the wrong member).
  const auto defaults = Config().fields();
  for (std::size_t k = 0; k < defaults.size(); ++k) {
    const auto& [name, value] = defaults[k];
    std::string other;
    if (value == "true" || value == "false")
      other = value == "true" ? "false" : "true";
    else if (name == "regularizer")
      other = value == "tv" ? "quadratic" : "tv";
    else if (name == "backend")
      other = value == "cpu" ? "cuda" : "cpu";
    else
      other = std::to_string(std::stoll(value.substr(0, value.find_first_of(".e"))) + 7);
    Config c;
    c.set(name, other);
    const auto changed = c.fields();
    for (std::size_t j = 0; j < defaults.size(); ++j) {
      if (j == k)
        EXPECT_NE(changed[j].second, defaults[j].second) << "set(" << name << ", " << other << ") had no effect";
      else
        EXPECT_EQ(changed[j], defaults[j]) << "set(" << name << ") changed " << defaults[j].first;
    }
  }
}

TEST(Config, SetChangesTheNamedField) {
  Config c;
  c.set("max_depth", "4.25");
  EXPECT_DOUBLE_EQ(c.max_depth, 4.25);
  c.set("initial_labels", "12");
  EXPECT_EQ(c.initial_labels, 12);
  c.set("seed", "42");
  EXPECT_EQ(c.seed, 42u);
  c.set("detect_occlusions", "false");
  EXPECT_FALSE(c.detect_occlusions);
  c.set("detect_occlusions", "1");
  EXPECT_TRUE(c.detect_occlusions);
  c.set("regularizer", "tv");
  EXPECT_EQ(c.regularizer, Regularizer::TotalVariation);
  EXPECT_DOUBLE_EQ(c.lambda(), c.lambda_tv);
  c.set("backend", "cpu");
  EXPECT_EQ(c.backend, Backend::Cpu);
  c.set("occlusion_kz", "1e-3");
  EXPECT_DOUBLE_EQ(c.occlusion_kz, 1e-3);

  // A changed config round-trips through its own fields too.
  Config copy;
  for (const auto& [name, value] : c.fields()) copy.set(name, value);
  EXPECT_EQ(copy.fields(), c.fields());
}

TEST(Config, SetRejectsUnknownNamesAndBadText) {
  Config c;
  auto expectThrowNaming = [&](const std::string& name, const std::string& value, const std::string& needle) {
    try {
      c.set(name, value);
      ADD_FAILURE() << name << " = " << value << " accepted";
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expectThrowNaming("no_such_field", "1", "no_such_field");
  expectThrowNaming("max_depth", "five", "max_depth");
  expectThrowNaming("max_depth", "5m", "5m");
  expectThrowNaming("initial_labels", "2.5", "initial_labels");
  expectThrowNaming("seed", "-1", "seed");
  expectThrowNaming("verbose", "yes", "verbose");
  expectThrowNaming("regularizer", "l1", "l1");
  expectThrowNaming("backend", "opencl", "opencl");
  EXPECT_EQ(c.fields(), Config().fields()) << "a rejected set() must not change the config";
}

TEST(Config, EnumTextRoundTrips) {
  for (Regularizer r : {Regularizer::Quadratic, Regularizer::TotalVariation})
    EXPECT_EQ(parseRegularizer(toString(r)), r);
  for (Backend b : {Backend::Auto, Backend::Cpu, Backend::Cuda}) EXPECT_EQ(parseBackend(toString(b)), b);
  EXPECT_EQ(parseRegularizer("quad"), Regularizer::Quadratic);
  EXPECT_THROW(parseBackend("tpu"), ConfigError);
}

}  // namespace
}  // namespace mc_flow
