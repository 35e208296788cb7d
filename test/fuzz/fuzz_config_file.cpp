// Solver configuration files as `mcflow run --config` reads them (io::applyConfigFile, JSON or YAML), then
// validated as the tool does before solving.
#include "fuzz_common.h"
#include "mc_flow/io/config_file.h"

using namespace mc_flow;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const fuzz::InputFile file(data, size, ".yaml");
  fuzz::loadOrRefuse([&] {
    Config config;
    io::applyConfigFile(file.path(), config);
    config.validate();
  });
  return 0;
}
