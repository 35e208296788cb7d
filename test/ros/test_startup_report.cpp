// What the nodelet does and says once, without a node: the folder for saved pictures, the start-up text, the backend.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include <unistd.h>

#include "mc_flow/ros/startup_report.h"

namespace mc_flow_ros {
namespace {

namespace fs = std::filesystem;

/// A fresh folder under the system's temporary one, removed at the end.
struct TemporaryFolder {
  TemporaryFolder() : path(fs::temp_directory_path() / ("mc_flow_startup_" + std::to_string(::getpid()))) {
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TemporaryFolder() { fs::remove_all(path); }
  fs::path path;
};

TEST(StartupReport, TheSaveFolderIsCreatedWithItsParentsOrNamedWhenItCannotBe) {
  EXPECT_FALSE(makeSaveDir(""));
  TemporaryFolder folder;
  const fs::path nested = folder.path / "a" / "b";
  EXPECT_FALSE(makeSaveDir(nested.string()));
  EXPECT_TRUE(fs::is_directory(nested));
  EXPECT_FALSE(makeSaveDir(nested.string()));  // it exists already

  // A file where the folder should be, and a folder below a file: named, with the file system's reason.
  const fs::path file = folder.path / "file";
  std::ofstream(file) << "x";
  for (const fs::path& dir : {file, file / "pictures"}) {
    const std::string problem = makeSaveDir(dir.string()).value_or("(none)");
    EXPECT_EQ(problem.rfind("save_dir '" + dir.string() + "' cannot be created (", 0), 0u) << problem;
    EXPECT_NE(problem.find("); pictures will not be saved"), std::string::npos) << problem;
  }
}

TEST(StartupReport, TheStartupTextNamesInputsOutputsAndEveryParameter) {
  NodeParameters params;
  mc_flow::Config solver;
  solver.set("outer_iterations", "7");
  const std::array<std::string, 3> inputs = {"/camera/rgb/image_rect_color", "/camera/depth_registered/image_rect",
                                             "/camera/rgb/camera_info"};
  const std::string text = startupText("/mc_flow", params, inputs, "/mc_flow/segments /mc_flow/labels", solver);
  EXPECT_EQ(text.rfind("MC-Flow nodelet /mc_flow started.\n  inputs (synchronised, approximate time): "
                       "/camera/rgb/image_rect_color, /camera/depth_registered/image_rect, /camera/rgb/camera_info "
                       "(image_transport, parameter image_transport selects the transport)\n"
                       "  outputs: /mc_flow/segments /mc_flow/labels\n  node parameters: " +
                           params.describe() + "\n  solver parameters (dynamic_reconfigure):",
                       0),
            0u)
      << text;
  for (const auto& [name, value] : solver.fields())
    EXPECT_NE(text.find(" " + name + "=" + value), std::string::npos) << name;
  EXPECT_NE(text.find(" outer_iterations=7"), std::string::npos) << text;

  params.approximate_sync = false;
  EXPECT_NE(startupText("/mc_flow", params, inputs, "", solver).find("(synchronised, exact time)"), std::string::npos);
}

mc_flow::Result solvedOn(mc_flow::Backend kind, const std::string& note) {
  mc_flow::Result result;
  result.backend_kind = kind;
  result.backend = mc_flow::toString(kind);
  result.backend_note = note;
  return result;
}

mc_flow::Config asking(mc_flow::Backend backend, int cuda_device = 0) {
  mc_flow::Config config;
  config.backend = backend;
  config.cuda_device = cuda_device;
  return config;
}

TEST(StartupReport, TheBackendThatSolvesIsSaidAsInfo) {
  const BackendReport gpu =
      backendReport(solvedOn(mc_flow::Backend::Cuda, "device 0: H100"), asking(mc_flow::Backend::Auto));
  EXPECT_FALSE(gpu.warning);
  EXPECT_EQ(gpu.text, "solver backend: cuda (device 0: H100)");
  EXPECT_EQ(gpu.debug, "");
  const BackendReport cpu = backendReport(solvedOn(mc_flow::Backend::Cpu, "requested"), asking(mc_flow::Backend::Cpu));
  EXPECT_FALSE(cpu.warning);
  EXPECT_EQ(cpu.text, "solver backend: cpu (requested)");
}

TEST(StartupReport, NoGpuUnderAutoIsInfoWithTheRuntimesWordsAtDebugLevel) {
  const BackendReport r = backendReport(solvedOn(mc_flow::Backend::Cpu, "CUDA driver version is insufficient"),
                                        asking(mc_flow::Backend::Auto));
  EXPECT_FALSE(r.warning);
  EXPECT_EQ(r.text, "no usable NVIDIA GPU/driver found: running on the CPU");
  EXPECT_EQ(r.debug, "CUDA detail: CUDA driver version is insufficient");
}

TEST(StartupReport, AGpuAskedForAndNotUsedIsAWarningWithItsReason) {
  const BackendReport device =
      backendReport(solvedOn(mc_flow::Backend::Cpu, "1 device"), asking(mc_flow::Backend::Auto, 2));
  EXPECT_TRUE(device.warning);
  EXPECT_EQ(device.text, "cuda_device 2 cannot be used: running on the CPU (1 device)");
  const BackendReport cuda =
      backendReport(solvedOn(mc_flow::Backend::Cpu, "no device"), asking(mc_flow::Backend::Cuda));
  EXPECT_TRUE(cuda.warning);
  EXPECT_EQ(cuda.text, "backend 'cuda' was requested but cannot be used: running on the CPU (no device)");
  EXPECT_EQ(cuda.debug, "");
}

}  // namespace
}  // namespace mc_flow_ros
