// Middlebury .flo as `mcflow eval` reads optical_flow.flo and gt_optical_flow.flo (io::readFlo).
#include "fuzz_common.h"
#include "mc_flow/io/flow_io.h"

using namespace mc_flow;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fuzz::InputFile file(data, size, ".flo");
  fuzz::loadOrRefuse([&] { fuzz::checkShape(io::readFlo(file.path()), 2, "flow"); });
  return 0;
}
