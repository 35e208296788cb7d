/**
 * @file text.h
 * @brief Small text helpers shared by the parsers of the io library.
 */
#pragma once

#include <string>

namespace mc_flow {
namespace io {

/// @brief `s` without leading and trailing spaces, tabs and line breaks.
inline std::string trimWhitespace(const std::string& s) {
  const std::size_t b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const std::size_t e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

}  // namespace io
}  // namespace mc_flow
