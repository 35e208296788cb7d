// A real sequence in PFM files (sequence_folder.h): mcflow export-seq writes it, mcflow_bench_stream --sequence reads
// it.
#include "mc_flow/eval/sequence_folder.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "mc_flow/core/error.h"
#include "mc_flow/io/flow_io.h"

namespace mc_flow {
namespace {

std::string framePath(const std::string& dir, const char* kind, std::size_t index) {
  char name[48];
  std::snprintf(name, sizeof(name), "%s_%05zu.pfm", kind, index);
  return (std::filesystem::path(dir) / name).string();
}

}  // namespace

void writeSequenceFrame(const std::string& dir, std::size_t index, const RgbdFrame& frame) {
  std::filesystem::create_directories(dir);
  io::writePfm(framePath(dir, "intensity", index), frame.intensity);
  io::writePfm(framePath(dir, "depth", index), frame.depth);
}

void writeSequenceIndex(const std::string& dir, const Intrinsics& K, const std::vector<double>& stamps) {
  std::filesystem::create_directories(dir);
  const std::filesystem::path folder(dir);
  std::ostringstream intrinsics, list;
  intrinsics.precision(17);
  intrinsics << K.fx << " " << K.fy << " " << K.cx << " " << K.cy << "\n";
  io::writeTextFile((folder / "intrinsics.txt").string(), intrinsics.str());
  list.precision(17);
  for (const double stamp : stamps) list << stamp << "\n";
  io::writeTextFile((folder / "stamps.txt").string(), list.str());
}

RgbdFrame SequenceFolder::frame(std::size_t index) const {
  if (index >= stamps.size())
    throw InputError("sequence folder " + dir + ": frame index " + std::to_string(index) + " is past the last frame (" +
                     std::to_string(stamps.size()) + " frames in stamps.txt)");
  RgbdFrame f;
  f.intensity = io::readPfm(framePath(dir, "intensity", index));
  f.depth = io::readPfm(framePath(dir, "depth", index));
  if (f.intensity.channels != 1 || f.depth.channels != 1 || !f.intensity.sameSize(f.depth.width, f.depth.height))
    throw InputError("sequence folder " + dir + ": frame " + std::to_string(index) + ": intensity " +
                     imageSizeText(f.intensity) + " and depth " + imageSizeText(f.depth) +
                     ": expected one-channel images of one size");
  return f;
}

SequenceFolder readSequenceFolder(const std::string& dir) {
  const std::filesystem::path folder(dir);
  SequenceFolder out;
  out.dir = dir;
  const std::string intrinsics_path = (folder / "intrinsics.txt").string();
  std::ifstream intrinsics(intrinsics_path);
  if (!intrinsics) throw InputError(intrinsics_path + ": cannot be opened (write the folder with mcflow export-seq)");
  if (!(intrinsics >> out.K.fx >> out.K.fy >> out.K.cx >> out.K.cy))
    throw InputError(intrinsics_path + ": expected four numbers fx fy cx cy");
  try {
    out.K.validate();
  } catch (const InputError& e) {
    throw InputError(intrinsics_path + ": " + e.what());
  }
  const std::string stamps_path = (folder / "stamps.txt").string();
  std::ifstream list(stamps_path);
  if (!list) throw InputError(stamps_path + ": cannot be opened");
  std::string line;
  int number = 0;
  while (std::getline(list, line)) {
    ++number;
    std::istringstream in(line);
    double stamp = NAN;
    std::string rest;
    if (!(in >> stamp) || !std::isfinite(stamp) || (in >> rest))
      throw InputError(stamps_path + ":" + std::to_string(number) + ": expected one stamp [s], got '" + line + "'");
    out.stamps.push_back(stamp);
  }
  if (out.stamps.size() < 2)
    throw InputError(stamps_path + ": " + std::to_string(out.stamps.size()) + " frame(s), a sequence needs 2");
  return out;
}

}  // namespace mc_flow
