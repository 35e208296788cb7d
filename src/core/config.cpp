#include "mc_flow/core/config.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
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

// One table drives set() and fields(), so a field's name and type are written down once.
using FieldPointer = std::variant<double Config::*, int Config::*, unsigned Config::*, bool Config::*,
                                  Regularizer Config::*, Backend Config::*>;
struct FieldEntry {
  const char* name;
  FieldPointer pointer;
};

#define MCFLOW_FIELD(member) FieldEntry{#member, &Config::member}
const FieldEntry kFields[] = {
    MCFLOW_FIELD(max_depth),
    MCFLOW_FIELD(min_depth),
    MCFLOW_FIELD(coarsest_min_width),
    MCFLOW_FIELD(processing_level),
    MCFLOW_FIELD(depth_downsample_range),
    MCFLOW_FIELD(initial_labels),
    MCFLOW_FIELD(kmeans_max_iterations),
    MCFLOW_FIELD(kmeans_tolerance),
    MCFLOW_FIELD(kmeans_level_offset),
    MCFLOW_FIELD(seed),
    MCFLOW_FIELD(dominant_motion_init),
    MCFLOW_FIELD(outer_iterations),
    MCFLOW_FIELD(outer_convergence),
    MCFLOW_FIELD(label_level_offset),
    MCFLOW_FIELD(motion_iterations_per_level),
    MCFLOW_FIELD(motion_iterations_refine),
    MCFLOW_FIELD(motion_coarse_levels_after_first),
    MCFLOW_FIELD(alpha),
    MCFLOW_FIELD(cauchy_c_intensity),
    MCFLOW_FIELD(cauchy_c_depth),
    MCFLOW_FIELD(motion_damping),
    MCFLOW_FIELD(motion_min_update),
    MCFLOW_FIELD(min_label_weight),
    MCFLOW_FIELD(motion_min_label_pixels),
    MCFLOW_FIELD(regularizer),
    MCFLOW_FIELD(lambda_quadratic),
    MCFLOW_FIELD(lambda_tv),
    MCFLOW_FIELD(label_iterations),
    MCFLOW_FIELD(label_iterations_final),
    MCFLOW_FIELD(label_tolerance),
    MCFLOW_FIELD(outlier_cost),
    MCFLOW_FIELD(out_of_view_cost),
    MCFLOW_FIELD(min_geometric_weight),
    MCFLOW_FIELD(label_cost),
    MCFLOW_FIELD(max_splits_per_iteration),
    MCFLOW_FIELD(max_labels),
    MCFLOW_FIELD(min_support_fraction),
    MCFLOW_FIELD(detect_occlusions),
    MCFLOW_FIELD(occlusion_kz),
    MCFLOW_FIELD(occlusion_ko),
    MCFLOW_FIELD(warm_start),
    MCFLOW_FIELD(warm_outer_iterations),
    MCFLOW_FIELD(warm_motion_coarse_levels),
    MCFLOW_FIELD(warm_depth_tolerance),
    MCFLOW_FIELD(warm_min_coverage),
    MCFLOW_FIELD(warm_max_energy_ratio),
    MCFLOW_FIELD(id_min_overlap),
    MCFLOW_FIELD(backend),
    MCFLOW_FIELD(threads),
    MCFLOW_FIELD(verbose),
};
#undef MCFLOW_FIELD

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

// ---- range checks used by validate() ----
[[noreturn]] void rangeError(const char* name, const std::string& value, const std::string& rule) {
  throw ConfigError(std::string("Config.") + name + " = " + value + " is invalid: " + rule);
}
void requireFinite(const char* name, double v) {
  if (!std::isfinite(v)) rangeError(name, doubleText(v), "must be finite");
}
void requirePositive(const char* name, double v) {
  requireFinite(name, v);
  if (!(v > 0)) rangeError(name, doubleText(v), "must be > 0");
}
void requireNonNegative(const char* name, double v) {
  requireFinite(name, v);
  if (!(v >= 0)) rangeError(name, doubleText(v), "must be >= 0");
}
void requireFraction(const char* name, double v) {
  requireFinite(name, v);
  if (!(v >= 0 && v < 1)) rangeError(name, doubleText(v), "must be in [0, 1)");
}
void requireIntAtLeast(const char* name, int v, int lo) {
  if (v < lo) rangeError(name, std::to_string(v), "must be >= " + std::to_string(lo));
}
void requireIntIn(const char* name, int v, int lo, int hi) {
  if (v < lo || v > hi)
    rangeError(name, std::to_string(v), "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
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
  requirePositive("min_depth", min_depth);
  requirePositive("max_depth", max_depth);
  if (!(max_depth > min_depth))
    rangeError("max_depth", doubleText(max_depth), "must be > min_depth (" + doubleText(min_depth) + ")");

  requireIntAtLeast("coarsest_min_width", coarsest_min_width, 1);
  requireIntIn("processing_level", processing_level, 0, 10);
  requirePositive("depth_downsample_range", depth_downsample_range);

  requireIntIn("initial_labels", initial_labels, 1, 64);
  requireIntAtLeast("kmeans_max_iterations", kmeans_max_iterations, 1);
  requireNonNegative("kmeans_tolerance", kmeans_tolerance);
  requireIntIn("kmeans_level_offset", kmeans_level_offset, 0, 10);

  requireIntAtLeast("outer_iterations", outer_iterations, 1);
  requireNonNegative("outer_convergence", outer_convergence);
  requireIntIn("label_level_offset", label_level_offset, 0, 10);

  requireIntAtLeast("motion_iterations_per_level", motion_iterations_per_level, 1);
  requireIntAtLeast("motion_iterations_refine", motion_iterations_refine, 1);
  requireIntIn("motion_coarse_levels_after_first", motion_coarse_levels_after_first, 0, 10);
  requireNonNegative("alpha", alpha);
  requirePositive("cauchy_c_intensity", cauchy_c_intensity);
  requirePositive("cauchy_c_depth", cauchy_c_depth);
  requireNonNegative("motion_damping", motion_damping);
  requireNonNegative("motion_min_update", motion_min_update);
  requireFraction("min_label_weight", min_label_weight);
  requireNonNegative("motion_min_label_pixels", motion_min_label_pixels);

  if (regularizer != Regularizer::Quadratic && regularizer != Regularizer::TotalVariation)
    rangeError("regularizer", std::to_string(int(regularizer)), "unknown enum value");
  requirePositive("lambda_quadratic", lambda_quadratic);
  requirePositive("lambda_tv", lambda_tv);
  requireIntAtLeast("label_iterations", label_iterations, 1);
  requireIntAtLeast("label_iterations_final", label_iterations_final, 1);
  requireNonNegative("label_tolerance", label_tolerance);
  requirePositive("outlier_cost", outlier_cost);
  requireNonNegative("out_of_view_cost", out_of_view_cost);
  requirePositive("min_geometric_weight", min_geometric_weight);
  if (min_geometric_weight > 1)
    rangeError("min_geometric_weight", doubleText(min_geometric_weight), "must be <= 1 (weights are in (0, 1])");

  requireNonNegative("label_cost", label_cost);
  requireIntIn("max_splits_per_iteration", max_splits_per_iteration, 0, 16);
  requireIntIn("max_labels", max_labels, 1, 64);
  requireFraction("min_support_fraction", min_support_fraction);

  requireNonNegative("occlusion_kz", occlusion_kz);
  requireNonNegative("occlusion_ko", occlusion_ko);

  requireIntAtLeast("warm_outer_iterations", warm_outer_iterations, 1);
  requireIntIn("warm_motion_coarse_levels", warm_motion_coarse_levels, 0, 10);
  requirePositive("warm_depth_tolerance", warm_depth_tolerance);
  requireFraction("warm_min_coverage", warm_min_coverage);
  if (!(warm_max_energy_ratio >= 1) || !std::isfinite(warm_max_energy_ratio))
    rangeError("warm_max_energy_ratio", doubleText(warm_max_energy_ratio), "must be finite and >= 1");
  requireFraction("id_min_overlap", id_min_overlap);

  if (backend != Backend::Auto && backend != Backend::Cpu && backend != Backend::Cuda)
    rangeError("backend", std::to_string(int(backend)), "unknown enum value");
  requireIntIn("threads", threads, 0, 1024);
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
    const std::string text = std::visit(Overloaded{
                                            [&](double Config::*p) { return doubleText(this->*p); },
                                            [&](int Config::*p) { return std::to_string(this->*p); },
                                            [&](unsigned Config::*p) { return std::to_string(this->*p); },
                                            [&](bool Config::*p) { return std::string(this->*p ? "true" : "false"); },
                                            [&](Regularizer Config::*p) { return toString(this->*p); },
                                            [&](Backend Config::*p) { return toString(this->*p); },
                                        },
                                        field.pointer);
    out.emplace_back(field.name, text);
  }
  return out;
}

}  // namespace mc_flow
