/**
 * @file input_error.h
 * @brief The named problems an input message can have; the nodelet counts and throttles warnings per kind.
 */
#pragma once

#include <algorithm>
#include <cctype>
#include <string>

#include "mc_flow/core/error.h"

namespace mc_flow_ros {

/// @brief What was wrong with an input frame.
enum class InputProblem {
  Encoding,    ///< an encoding the package does not read
  Layout,      ///< width/height/step/data size/byte order inconsistent: the buffer cannot be read safely
  Size,        ///< consistent but unusable sizes (too large, too small, colour/depth aspect mismatch)
  Depth,       ///< no valid depth
  Intrinsics,  ///< camera_info unusable (zero or non-finite values)
};

/// @brief Short lower-case name of a problem ("encoding", "layout", ...), for keys and diagnostics.
inline const char* inputProblemName(InputProblem problem) {
  switch (problem) {
    case InputProblem::Encoding: return "encoding";
    case InputProblem::Layout: return "layout";
    case InputProblem::Size: return "size";
    case InputProblem::Depth: return "depth";
    case InputProblem::Intrinsics: return "intrinsics";
  }
  return "input";
}

/// @brief Thrown by the input validation and conversions; the message names the offending value.
struct FrameInputError : mc_flow::InputError {
  FrameInputError(InputProblem kind, const std::string& message) : mc_flow::InputError(message), problem(kind) {}
  InputProblem problem;
};

/// @brief The key that throttles warnings about `e`: its problem's name and its text without digits, so that the same
/// fault in every frame (sizes, stamps and counts differ) is one key.
inline std::string inputWarningKey(const FrameInputError& e) {
  std::string key = std::string(inputProblemName(e.problem)) + ":" + e.what();
  key.erase(std::remove_if(key.begin(), key.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); }),
            key.end());
  return key;
}

}  // namespace mc_flow_ros
