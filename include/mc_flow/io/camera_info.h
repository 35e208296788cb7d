/**
 * @file camera_info.h
 * @brief Intrinsics from text: "FX,FY,CX,CY" and ROS camera_info YAML (K or P, either the message form
 * `K: [...]` as `rostopic echo` prints it or the camera_calibration_parsers form `camera_matrix: {data: [...]}`),
 * read with yaml-cpp.
 */
#pragma once

#include <string>

#include "mc_flow/core/image.h"

namespace mc_flow {
namespace io {

/// @brief Intrinsics plus the image size the calibration was made at (0 when the file does not say).
struct CameraInfo {
  Intrinsics intrinsics;
  int width = 0, height = 0;
};

/// @brief Parses "FX,FY,CX,CY" [px]. Throws InputError quoting the text when it is malformed, or naming the
/// value when a focal length is not > 0 or a value is not finite.
Intrinsics parseIntrinsics(const std::string& text);
/// @brief "fx,fy,cx,cy" with enough digits to parse back exactly.
std::string formatIntrinsics(const Intrinsics& K);

/// @brief Parses camera_info YAML text. K is preferred; P (its left 3x3) is used when K is missing or zero.
/// `what` names the source in error messages.
CameraInfo parseCameraInfoYaml(const std::string& text, const std::string& what);
/// @brief Loads a camera_info YAML file (throws InputError naming the file).
CameraInfo loadCameraInfo(const std::string& path);
/// @brief Writes a camera_info YAML (message form with K, D, R, P, width, height; no distortion).
void saveCameraInfo(const std::string& path, const CameraInfo& info);

/// @brief Throws InputError naming `what` and the value when fx/fy are not > 0 or a value is not finite.
void checkIntrinsics(const Intrinsics& K, const std::string& what);

}  // namespace io
}  // namespace mc_flow
