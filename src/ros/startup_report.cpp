#include "mc_flow/ros/startup_report.h"

#include <filesystem>
#include <sstream>
#include <system_error>

namespace mc_flow_ros {

std::optional<std::string> makeSaveDir(const std::string& dir) {
  if (dir.empty()) return std::nullopt;
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (!error && std::filesystem::is_directory(dir, error)) return std::nullopt;
  return "save_dir '" + dir + "' cannot be created (" + (error ? error.message() : "it exists and is not a folder") +
         "); pictures will not be saved";
}

std::string startupText(const std::string& name, const NodeParameters& params, const std::array<std::string, 3>& inputs,
                        const std::string& outputs, const mc_flow::Config& solver) {
  std::ostringstream s;
  s << "MC-Flow nodelet " << name << " started.\n  inputs (synchronised, "
    << (params.approximate_sync ? "approximate" : "exact") << " time): " << inputs[0] << ", " << inputs[1] << ", "
    << inputs[2] << " (image_transport, parameter image_transport selects the transport)\n  outputs: " << outputs
    << "\n  node parameters: " << params.describe() << "\n  solver parameters (dynamic_reconfigure):";
  for (const auto& [field, value] : solver.fields()) s << " " << field << "=" << value;
  return s.str();
}

BackendReport backendReport(const mc_flow::Result& result, const mc_flow::Config& config) {
  const mc_flow::Backend requested = config.backend;
  if (result.backend_kind == mc_flow::Backend::Cuda || requested == mc_flow::Backend::Cpu) {
    return {false, "solver backend: " + result.backend + " (" + result.backend_note + ")", ""};
  }
  if (requested == mc_flow::Backend::Auto && config.cuda_device != 0) {
    // A GPU other than the first was asked for: its absence is a configuration problem, said with its reason.
    return {true,
            "cuda_device " + std::to_string(config.cuda_device) + " cannot be used: running on the CPU (" +
                result.backend_note + ")",
            ""};
  }
  if (requested == mc_flow::Backend::Auto) {
    // The usual case on a machine without an NVIDIA GPU: the CUDA runtime's own words ("driver version is
    // insufficient") read as a request to upgrade a driver, so they go to debug level.
    return {false, "no usable NVIDIA GPU/driver found: running on the CPU", "CUDA detail: " + result.backend_note};
  }
  // The pipeline could not make the CUDA backend and solves on the CPU (SequencePipeline's fallback): one warning with
  // the reason, which names the device and the device count when cuda_device does not exist.
  return {true, "backend 'cuda' was requested but cannot be used: running on the CPU (" + result.backend_note + ")",
          ""};
}

}  // namespace mc_flow_ros
