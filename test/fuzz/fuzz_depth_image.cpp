// Depth images as `mcflow run --depth1/--depth2` reads them through OpenCV (io::loadDepth on any name but
// .pfm): 16-bit PNG/PGM in millimetres, 32-bit float TIFF/EXR in metres.
#include "fuzz_common.h"
#include "mc_flow/io/image_io.h"

using namespace mc_flow;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fuzz::InputFile file(data, size, ".png");
  fuzz::loadOrRefuse([&] { fuzz::checkShape(io::loadDepth(file.path(), 1000.0), 1, "depth"); });
  return 0;
}
