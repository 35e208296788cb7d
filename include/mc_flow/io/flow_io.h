/**
 * @file flow_io.h
 * @brief File formats that need no OpenCV: dense float files (Middlebury .flo, PFM and NumPy .npy, writers and
 * readers) and the TUM RGB-D trajectory line (for the core-only benchmarks too).
 *
 * .flo: "PIEH", width, height (int32), then (u, v) float32 per pixel, row-major, little endian.
 * .pfm: "PF" (3 channels) or "Pf" (1 channel), width height, scale (negative = little endian), rows stored
 * bottom-to-top. .npy: format version 1.0, '<f4', C order. NaN values are kept as they are.
 */
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "mc_flow/core/image.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {
namespace io {

/// @brief A file could not be created or written.
struct FileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// @brief Writes a 2-channel flow image [px] as Middlebury .flo.
void writeFlo(const std::string& path, const ImageF& flow);
/// @brief Reads a Middlebury .flo file (2 channels). Throws InputError naming the file on a bad header/size.
ImageF readFlo(const std::string& path);

/// @brief Writes a 1- or 3-channel float image as PFM (little endian, first row of the image at the top).
void writePfm(const std::string& path, const ImageF& image);
/// @brief Reads a PFM file of either endianness into a top-row-first image.
ImageF readPfm(const std::string& path);

/// @brief Writes `text` to `path`; throws FileError naming the path.
void writeTextFile(const std::string& path, const std::string& text);
/// @brief Reads a whole file; throws InputError naming the path.
std::string readTextFile(const std::string& path);

/// @brief One line of a TUM RGB-D trajectory file: "stamp tx ty tz qx qy qz qw" (the pose's translation [m] and
/// rotation as a unit quaternion).
std::string tumTrajectoryLine(double stamp, const Eigen::Matrix4d& pose);

/// @brief A float32 array read from a .npy file.
struct NpyArray {
  std::vector<std::size_t> shape;
  std::vector<float> data;  ///< C order
};

/// @brief Writes a float32 C-order array of the given shape as .npy v1.0.
void writeNpy(const std::string& path, const std::vector<std::size_t>& shape, const std::vector<float>& data);
/// @brief Reads a '<f4', C-order .npy file (v1.0 or v2.0 header).
NpyArray readNpy(const std::string& path);

/// @brief Writes soft labels as an H x W x n array (pixel-major, planes as the last axis).
void writeSoftLabelsNpy(const std::string& path, const SoftLabels& labels);
/// @brief Reads an H x W x n array back into label-major SoftLabels.
SoftLabels readSoftLabelsNpy(const std::string& path);

}  // namespace io
}  // namespace mc_flow
