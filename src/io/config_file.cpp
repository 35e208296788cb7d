#include "mc_flow/io/config_file.h"

#include <algorithm>
#include <sstream>

#include "mc_flow/core/error.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"

namespace mc_flow {
namespace io {
namespace {

std::string trim(const std::string& s) {
  const std::size_t b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const std::size_t e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::string unquote(const std::string& s) {
  if (s.size() >= 2 && ((s.front() == '"' && s.back() == '"') || (s.front() == '\'' && s.back() == '\'')))
    return s.substr(1, s.size() - 2);
  return s;
}

// A flat JSON object: {"name": value, ...} with scalar values (numbers, strings, true/false).
std::vector<std::pair<std::string, std::string>> parseFlatJson(const std::string& text, const std::string& what) {
  std::vector<std::pair<std::string, std::string>> out;
  std::size_t i = text.find('{');
  auto fail = [&](const std::string& why) {
    const int line = 1 + int(std::count(text.begin(), text.begin() + std::min(i, text.size()), '\n'));
    throw ConfigError(what + ", line " + std::to_string(line) + ": " + why);
  };
  auto skipSpace = [&] {
    while (i < text.size() && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  };
  auto readString = [&] {
    if (text[i] != '"') fail("expected a quoted string");
    std::string s;
    for (++i; i < text.size() && text[i] != '"'; ++i) {
      if (text[i] == '\\' && i + 1 < text.size()) ++i;
      s.push_back(text[i]);
    }
    if (i >= text.size()) fail("unterminated string");
    ++i;
    return s;
  };
  ++i;
  skipSpace();
  if (i < text.size() && text[i] == '}') return out;
  while (i < text.size()) {
    skipSpace();
    const std::string key = readString();
    skipSpace();
    if (i >= text.size() || text[i] != ':') fail("expected ':' after \"" + key + "\"");
    ++i;
    skipSpace();
    if (i >= text.size()) fail("missing value of \"" + key + "\"");
    std::string value;
    if (text[i] == '"') {
      value = readString();
    } else if (text[i] == '{' || text[i] == '[') {
      fail("value of \"" + key + "\" must be a number, string or boolean (nested values are not Config fields)");
    } else {
      const std::size_t end = text.find_first_of(",}\n", i);
      value = trim(text.substr(i, end == std::string::npos ? std::string::npos : end - i));
      i = end == std::string::npos ? text.size() : end;
    }
    out.emplace_back(key, value);
    skipSpace();
    if (i < text.size() && text[i] == ',') {
      ++i;
      continue;
    }
    if (i < text.size() && text[i] == '}') return out;
    fail("expected ',' or '}'");
  }
  fail("missing closing '}'");
  return out;
}

std::vector<std::pair<std::string, std::string>> parseFlatYaml(const std::string& text, const std::string& what) {
  std::vector<std::pair<std::string, std::string>> out;
  std::istringstream in(text);
  std::string raw;
  int line_number = 0;
  while (std::getline(in, raw)) {
    ++line_number;
    // A '#' starts a comment unless it is inside quotes (values here never contain quotes and '#').
    const std::size_t hash = raw.find(" #");
    if (raw.rfind('#', 0) == 0) raw.clear();
    else if (hash != std::string::npos) raw = raw.substr(0, hash);
    const std::string body = trim(raw);
    if (body.empty() || body == "---" || body.rfind("%YAML", 0) == 0) continue;
    const std::size_t colon = body.find(':');
    const std::string where = what + ", line " + std::to_string(line_number);
    if (colon == std::string::npos) throw ConfigError(where + ": expected 'name: value', got '" + body + "'");
    if (raw.find_first_not_of(" \t") != 0)
      throw ConfigError(where + ": nested values are not Config fields ('" + body + "')");
    const std::string key = unquote(trim(body.substr(0, colon)));
    const std::string value = unquote(trim(body.substr(colon + 1)));
    if (value.empty()) throw ConfigError(where + ": '" + key + "' has no value");
    out.emplace_back(key, value);
  }
  return out;
}

}  // namespace

std::vector<std::pair<std::string, std::string>> parseFlatKeyValues(const std::string& text, const std::string& what) {
  const std::size_t first = text.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && text[first] == '{') return parseFlatJson(text, what);
  return parseFlatYaml(text, what);
}

void applyConfigFile(const std::string& path, Config& config) {
  if (!fileExists(path)) throw ConfigError("config file '" + path + "': file does not exist");
  const std::string what = "config file '" + path + "'";
  for (const auto& [key, value] : parseFlatKeyValues(readTextFile(path), what)) {
    try {
      config.set(key, value);
    } catch (const std::exception& e) {
      throw ConfigError(what + ", key '" + key + "' = '" + value + "': " + e.what());
    }
  }
}

void applyConfigAssignment(const std::string& assignment, Config& config) {
  const std::size_t eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw ConfigError("--set '" + assignment + "': expected name=value");
  try {
    config.set(trim(assignment.substr(0, eq)), trim(assignment.substr(eq + 1)));
  } catch (const std::exception& e) {
    throw ConfigError("--set '" + assignment + "': " + e.what());
  }
}

}  // namespace io
}  // namespace mc_flow
