/**
 * @file startup_report.h
 * @brief What the nodelet does and says once: the folder for saved pictures, the start-up description (every input,
 * output and parameter, the way rtabmap_ros logs them) and which backend solves (said at the first solved pair). Pure
 * but for the folder, so that every text is unit-tested without a node (test/ros/test_startup_report.cpp).
 */
#pragma once

#include <array>
#include <optional>
#include <string>

#include "mc_flow/core/config.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/ros/node_parameters.h"

namespace mc_flow_ros {

/// @brief Creates `dir` and its parents when `dir` is set. Returns the error to log when it cannot be created or is
/// not a folder (the caller then saves no pictures); nothing when `dir` is empty or a folder.
std::optional<std::string> makeSaveDir(const std::string& dir);

/// @brief The start-up log: the nodelet `name`, its inputs (`inputs`: the rgb, depth and camera_info topics) and how
/// they are synchronised, its outputs (`outputs`: OutputPublishers::topics()), every node parameter and every solver
/// parameter (`solver`: dynamic_reconfigure's first values).
std::string startupText(const std::string& name, const NodeParameters& params, const std::array<std::string, 3>& inputs,
                        const std::string& outputs, const mc_flow::Config& solver);

/// @brief What to say once about the backend that solves.
struct BackendReport {
  bool warning = false;  ///< a configuration problem (a GPU was asked for and is not used): a warning, else info
  std::string text;
  std::string debug;  ///< more detail for the debug level ("" none)
};

/// @brief The report for the first `result` solved with `config`. Running on the CPU without a usable GPU is normal
/// under backend auto (info, the CUDA runtime's words only at debug level); a warning when CUDA or a cuda_device other
/// than the first was asked for and the CPU solves.
BackendReport backendReport(const mc_flow::Result& result, const mc_flow::Config& config);

}  // namespace mc_flow_ros
