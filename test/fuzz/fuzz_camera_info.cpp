// camera_info YAML as `mcflow run --camera-info` reads it (io::loadCameraInfo). What it returns must be
// usable: finite intrinsics with positive focal lengths, and no negative image size.
#include <cmath>

#include "fuzz_common.h"
#include "mc_flow/io/camera_info.h"

using namespace mc_flow;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fuzz::InputFile file(data, size, ".yaml");
  fuzz::loadOrRefuse([&] {
    const io::CameraInfo info = io::loadCameraInfo(file.path());
    const Intrinsics& K = info.intrinsics;
    if (!(K.fx > 0 && K.fy > 0 && std::isfinite(K.fx) && std::isfinite(K.fy) && std::isfinite(K.cx) &&
          std::isfinite(K.cy) && info.width >= 0 && info.height >= 0))
      fuzz::finding("unusable camera info accepted");
  });
  return 0;
}
