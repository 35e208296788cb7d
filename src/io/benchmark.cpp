#include "mc_flow/io/benchmark.h"

#include <filesystem>

#include "mc_flow/core/error.h"
#include "mc_flow/io/image_io.h"

namespace mc_flow {
namespace io {

namespace {

constexpr double kRealPairDepthScale = 5000.0;  // TUM convention: value / 5000 = metres

}  // namespace

RealPair loadRealPair(const std::string& data_dir, const std::string& name, int halvings, const Config& config) {
  if (halvings < 0) throw InputError("loadRealPair: halvings = " + std::to_string(halvings) + " must be >= 0");
  const std::filesystem::path dir = std::filesystem::path(data_dir) / name;
  for (const char* file : {"color0.png", "depth0.png", "color1.png", "depth1.png"})
    if (!fileExists((dir / file).string()))
      throw InputError("real pair '" + name + "': missing file " + (dir / file).string());
  RgbdFrame frame1 = loadRgbdFrame((dir / "color0.png").string(), (dir / "depth0.png").string(), kRealPairDepthScale);
  RgbdFrame frame2 = loadRgbdFrame((dir / "color1.png").string(), (dir / "depth1.png").string(), kRealPairDepthScale);
  return prepareRealPair(name, std::move(frame1), std::move(frame2), (dir / "color0.png").string(), halvings, config);
}

}  // namespace io
}  // namespace mc_flow
