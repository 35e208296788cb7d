#include "mc_flow/core/config.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <type_traits>
#include <variant>

#include "mc_flow/core/error.h"

namespace mc_flow {

namespace {

std::string lowerCase(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

std::string trimmed(const std::string& s) {
  const auto first = s.find_first_not_of(" \t\r\n");
  if (first == std::string::npos) return std::string();
  const auto last = s.find_last_not_of(" \t\r\n");
  return s.substr(first, last - first + 1);
}

/// Shortest decimal text that parses back to exactly the same double (so fields() -> set() round-trips).
std::string doubleText(double v) {
  char buf[64];
  for (int precision = 6; precision <= 17; ++precision) {
    std::snprintf(buf, sizeof(buf), "%.*g", precision, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  return buf;
}

double parseDouble(const std::string& name, const std::string& text) {
  const std::string t = trimmed(text);
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(t.c_str(), &end);
  if (t.empty() || end != t.c_str() + t.size() || errno == ERANGE || !std::isfinite(v))
    throw ConfigError("Config." + name + ": '" + text + "' is not a finite number");
  return v;
}

long long parseInteger(const std::string& name, const std::string& text, long long lo, long long hi) {
  const std::string t = trimmed(text);
  char* end = nullptr;
  errno = 0;
  const long long v = std::strtoll(t.c_str(), &end, 10);
  if (t.empty() || end != t.c_str() + t.size() || errno == ERANGE)
    throw ConfigError("Config." + name + ": '" + text + "' is not an integer");
  if (v < lo || v > hi)
    throw ConfigError("Config." + name + ": " + text + " is outside the representable range [" + std::to_string(lo) +
                      ", " + std::to_string(hi) + "]");
  return v;
}

bool parseBool(const std::string& name, const std::string& text) {
  const std::string t = lowerCase(trimmed(text));
  if (t == "true" || t == "1") return true;
  if (t == "false" || t == "0") return false;
  throw ConfigError("Config." + name + ": '" + text + "' is not a boolean (true/false/1/0)");
}

// set() and fields() walk this list of member pointers, generated from config_fields.def.
using FieldPointer = std::variant<double Config::*, int Config::*, unsigned Config::*, bool Config::*,
                                  Regularizer Config::*, Backend Config::*>;
struct FieldEntry {
  const char* name;
  FieldPointer pointer;
};

const FieldEntry kFields[] = {
#define MCFLOW_SECTION(title)
#define MCFLOW_PARAM(type, name, default_value, min, max, unit, description) FieldEntry{#name, &Config::name},
#include "mc_flow/core/config_fields.def"
#undef MCFLOW_PARAM
#undef MCFLOW_SECTION
};

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

// ---- the text of a value, as set() parses it and fields() writes it ----
std::string valueText(double v) { return doubleText(v); }
std::string valueText(int v) { return std::to_string(v); }
std::string valueText(unsigned v) { return std::to_string(v); }
std::string valueText(bool v) { return v ? "true" : "false"; }
std::string valueText(Regularizer v) { return toString(v); }
std::string valueText(Backend v) { return toString(v); }

// ---- validate(): the table's inclusive [min, max] ----
[[noreturn]] void rangeError(const char* name, const std::string& value, const std::string& rule) {
  throw ConfigError(std::string("Config.") + name + " = " + value + " is invalid: " + rule);
}

template <class T>
void requireInRange(const char* name, T value, T lo, T hi, const char* unit) {
  if constexpr (std::is_same_v<T, bool>) {
    return;
  } else {
    bool inside;
    if constexpr (std::is_enum_v<T>) {
      using U = std::underlying_type_t<T>;
      inside = U(value) >= U(lo) && U(value) <= U(hi);
    } else {
      inside = value >= lo && value <= hi;  // false for NaN
    }
    if (!inside) {
      rangeError(name, valueText(value),
                 "must be in [" + valueText(lo) + ", " + valueText(hi) + "]" +
                     (std::string(unit) == "1" || std::string(unit) == "-" ? "" : std::string(" ") + unit));
    }
  }
}

}  // namespace

std::string toString(Regularizer r) {
  switch (r) {
    case Regularizer::Quadratic: return "quadratic";
    case Regularizer::TotalVariation: return "tv";
  }
  return "unknown(" + std::to_string(int(r)) + ")";
}

std::string toString(Backend b) {
  switch (b) {
    case Backend::Auto: return "auto";
    case Backend::Cpu: return "cpu";
    case Backend::Cuda: return "cuda";
  }
  return "unknown(" + std::to_string(int(b)) + ")";
}

Regularizer parseRegularizer(const std::string& s) {
  const std::string t = lowerCase(trimmed(s));
  if (t == "quad" || t == "quadratic") return Regularizer::Quadratic;
  if (t == "tv" || t == "totalvariation" || t == "total_variation") return Regularizer::TotalVariation;
  throw ConfigError("unknown regularizer '" + s + "' (expected quad, quadratic or tv)");
}

Backend parseBackend(const std::string& s) {
  const std::string t = lowerCase(trimmed(s));
  if (t == "auto") return Backend::Auto;
  if (t == "cpu") return Backend::Cpu;
  if (t == "cuda" || t == "gpu") return Backend::Cuda;
  throw ConfigError("unknown backend '" + s + "' (expected auto, cpu or cuda)");
}

void Config::validate() const {
#define MCFLOW_SECTION(title)
#define MCFLOW_PARAM(type, name, default_value, min, max, unit, description) \
  requireInRange<type>(#name, name, min, max, unit);
#include "mc_flow/core/config_fields.def"
#undef MCFLOW_PARAM
#undef MCFLOW_SECTION
  // Cross-field rules, which a per-field range cannot say.
  if (!(max_depth > min_depth))
    rangeError("max_depth", doubleText(max_depth), "must be > min_depth (" + doubleText(min_depth) + ")");
}

const std::vector<ConfigFieldInfo>& configFieldTable() {
  static const std::vector<ConfigFieldInfo> table = {
#define MCFLOW_SECTION(title)
#define MCFLOW_PARAM(type, name, default_value, min, max, unit, description)                                     \
  ConfigFieldInfo{#name, #type,      valueText(type(default_value)), valueText(type(min)), valueText(type(max)), \
                  unit,  description},
#include "mc_flow/core/config_fields.def"
#undef MCFLOW_PARAM
#undef MCFLOW_SECTION
  };
  return table;
}

void Config::set(const std::string& name, const std::string& value) {
  for (const FieldEntry& field : kFields) {
    if (name != field.name) continue;
    std::visit(Overloaded{
                   [&](double Config::*p) { this->*p = parseDouble(name, value); },
                   [&](int Config::*p) { this->*p = int(parseInteger(name, value, INT_MIN, INT_MAX)); },
                   [&](unsigned Config::*p) { this->*p = unsigned(parseInteger(name, value, 0, UINT_MAX)); },
                   [&](bool Config::*p) { this->*p = parseBool(name, value); },
                   [&](Regularizer Config::*p) {
                     try {
                       this->*p = parseRegularizer(value);
                     } catch (const ConfigError& e) {
                       throw ConfigError("Config." + name + ": " + e.what());
                     }
                   },
                   [&](Backend Config::*p) {
                     try {
                       this->*p = parseBackend(value);
                     } catch (const ConfigError& e) {
                       throw ConfigError("Config." + name + ": " + e.what());
                     }
                   },
               },
               field.pointer);
    return;
  }
  throw ConfigError("unknown Config field '" + name + "'");
}

std::vector<std::pair<std::string, std::string>> Config::fields() const {
  std::vector<std::pair<std::string, std::string>> out;
  out.reserve(sizeof(kFields) / sizeof(kFields[0]));
  for (const FieldEntry& field : kFields) {
    const std::string text = std::visit(
        Overloaded{
            [&](auto Config::*p) { return valueText(this->*p); },
        },
        field.pointer);
    out.emplace_back(field.name, text);
  }
  return out;
}

}  // namespace mc_flow
