/**
 * @file sequence_folder.h
 * @brief A real RGB-D sequence in files that need no OpenCV, for the GPU machine: `mcflow export-seq` writes the frames
 * as run-seq decodes them, `mcflow_bench_stream --sequence` reads them back bit for bit and solves them as run-seq
 * does.
 *
 * The folder: intrinsics.txt ("fx fy cx cy", 17 digits), stamps.txt (one stamp [s] per frame, 17 digits) and per frame
 * i intensity_NNNNN.pfm and depth_NNNNN.pfm (i with five digits; intensity in [0, 1], depth [m], 0 or NaN invalid).
 */
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "mc_flow/core/image.h"

namespace mc_flow {

/// @brief Writes frame `index` of a sequence folder (creating the folder).
void writeSequenceFrame(const std::string& dir, std::size_t index, const RgbdFrame& frame);

/// @brief Writes the folder's intrinsics.txt and stamps.txt: one stamp per frame written with writeSequenceFrame.
void writeSequenceIndex(const std::string& dir, const Intrinsics& K, const std::vector<double>& stamps);

/// @brief A sequence folder's index; frames are read one at a time.
struct SequenceFolder {
  std::string dir;
  Intrinsics K;
  std::vector<double> stamps;  ///< [s], one per frame
  /// @brief Frame `index`. Throws InputError naming a missing or malformed file, or an index past the last frame.
  RgbdFrame frame(std::size_t index) const;
};

/// @brief Reads a folder's intrinsics.txt and stamps.txt. Throws InputError naming a missing or malformed file (or a
/// folder without frames).
SequenceFolder readSequenceFolder(const std::string& dir);

}  // namespace mc_flow
