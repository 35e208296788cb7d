// PFM as `mcflow run --depth1 x.pfm` reads it (io::loadDepth -> io::readPfm, this library's own parser),
// and as `mcflow eval` reads scene_flow.pfm (io::readPfm, 1 or 3 channels).
#include "fuzz_common.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"

using namespace mc_flow;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fuzz::InputFile file(data, size, ".pfm");
  fuzz::loadOrRefuse([&] { fuzz::checkShape(io::loadDepth(file.path(), 1000.0), 1, "depth"); });
  fuzz::loadOrRefuse([&] {
    const ImageF image = io::readPfm(file.path());
    if (image.channels != 1 && image.channels != 3)
      fuzz::finding("PFM with " + std::to_string(image.channels) + " channels");
    fuzz::checkShape(image, image.channels, "pfm");
  });
  return 0;
}
