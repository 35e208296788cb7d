// Shared by the libFuzzer targets (docs/TESTING.md): the input as a file, since the loaders take paths, and
// the outcome a loader may have on a bad file. A refusal with the library's own error types is expected;
// anything else escaping a loader (another exception type, a crash, a sanitizer report, an image whose
// buffer does not match its size) is a finding.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>
#include <typeinfo>

#include "mc_flow/core/error.h"
#include "mc_flow/core/image.h"

namespace mc_flow {
namespace fuzz {

/// @brief The fuzz input written to `<tmp>/mcflow_fuzz_<pid><suffix>`, removed when this goes out of scope.
class InputFile {
 public:
  InputFile(const std::uint8_t* data, std::size_t size, const std::string& suffix)
      : path_((std::filesystem::temp_directory_path() / ("mcflow_fuzz_" + std::to_string(::getpid()) + suffix))
                  .string()) {
    std::ofstream out(path_, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
    if (!out) {
      std::fprintf(stderr, "fuzz: cannot write the input to %s\n", path_.c_str());
      std::abort();
    }
  }
  ~InputFile() {
    std::error_code ignored;
    std::filesystem::remove(path_, ignored);
  }
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;

  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

[[noreturn]] inline void finding(const std::string& what) {
  std::fprintf(stderr, "fuzz finding: %s\n", what.c_str());
  std::abort();
}

/// @brief Runs `load`; InputError and ConfigError are the refusals a bad file may get, anything else aborts.
template <class Load>
void loadOrRefuse(Load&& load) {
  try {
    load();
  } catch (const InputError&) {
  } catch (const ConfigError&) {
  } catch (const std::exception& e) {
    finding(std::string("unexpected exception ") + typeid(e).name() + ": " + e.what());
  }
}

/// @brief A loaded image must be non-empty and its buffer must hold exactly width x height x channels values.
template <class T>
void checkShape(const Image<T>& image, int channels, const char* what) {
  if (image.width <= 0 || image.height <= 0 || image.channels != channels ||
      image.data.size() != std::size_t(image.width) * std::size_t(image.height) * std::size_t(channels))
    finding(std::string(what) + ": inconsistent image " + std::to_string(image.width) + "x" +
            std::to_string(image.height) + "x" + std::to_string(image.channels) + " holding " +
            std::to_string(image.data.size()) + " values");
}

}  // namespace fuzz
}  // namespace mc_flow
