// Colour images as `mcflow run --rgb1/--rgb2` reads them (io::loadIntensity, decoded by OpenCV whatever the
// file name says: PNG, PGM, TIFF, EXR, ...).
#include "fuzz_common.h"
#include "mc_flow/io/image_io.h"

using namespace mc_flow;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fuzz::InputFile file(data, size, ".png");
  fuzz::loadOrRefuse([&] {
    ImageU8 rgb;
    const ImageF intensity = io::loadIntensity(file.path(), &rgb);
    fuzz::checkShape(intensity, 1, "intensity");
    fuzz::checkShape(rgb, 3, "rgb");
    if (!intensity.sameSize(rgb)) fuzz::finding("intensity and rgb differ in size");
  });
  return 0;
}
