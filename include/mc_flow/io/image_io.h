/**
 * @file image_io.h
 * @brief Loading and saving RGB-D frames: colour -> intensity in [0, 1], depth -> metres.
 *
 * Depth files: 16-bit unsigned PNG/PGM holding `depth_scale` units per metre (1000 = millimetres as the
 * ROS 16UC1 encoding, 5000 for TUM data), or 32-bit float (PFM/EXR/TIFF) in metres. 0 or NaN = no
 * measurement. Every error is an mc_flow::InputError (reading) or mc_flow::io::FileError (writing) whose
 * message names the file.
 */
#pragma once

#include <stdexcept>
#include <string>

#include <opencv2/core.hpp>

#include "mc_flow/core/image.h"
#include "mc_flow/io/flow_io.h"  // FileError

namespace mc_flow {
namespace io {

/// @brief Grey intensity in [0, 1] from an 8-bit or 16-bit image with 1, 3 (BGR, as OpenCV stores it)
/// or 4 (BGRA) channels: 0.299 R + 0.587 G + 0.114 B. `what` names the source in error messages.
ImageF intensityFromMat(const cv::Mat& image, const std::string& what);

/// @brief Depth in metres from a 16-bit unsigned image (value / depth_scale) or a 32-bit float image
/// (already metres). Other types throw InputError naming `what` and the type found.
ImageF depthFromMat(const cv::Mat& image, double depth_scale, const std::string& what);

/// @brief Loads a colour or grey image as intensity in [0, 1]; `rgb` (optional) receives 3-channel RGB 8-bit.
ImageF loadIntensity(const std::string& path, ImageU8* rgb = nullptr);

/// @brief Loads a depth image in metres (see file comment). `.pfm` is read by this library; other formats
/// by OpenCV. Throws InputError when no pixel holds a valid depth (> 0 and finite).
ImageF loadDepth(const std::string& path, double depth_scale);

/// @brief Loads one RGB-D frame and checks that colour and depth have the same size.
RgbdFrame loadRgbdFrame(const std::string& color_path, const std::string& depth_path, double depth_scale,
                        ImageU8* rgb = nullptr);

/// @brief Converts between the core's containers and OpenCV matrices (deep copies).
cv::Mat toMat(const ImageF& image);
cv::Mat toMat(const ImageU8& image);
ImageF toImageF(const cv::Mat& mat);

/// @brief Saves depth [m] as 16-bit PNG with `depth_scale` units per metre (rounded; invalid and
/// out-of-range values become 0).
void saveDepthPng16(const std::string& path, const ImageF& depth, double depth_scale);
/// @brief Saves an RGB 8-bit image (3 channels, R first) or a grey one.
void saveRgb(const std::string& path, const ImageU8& rgb);
/// @brief Saves a single-channel 8-bit mask.
void saveMask(const std::string& path, const ImageU8& mask);
/// @brief Saves a label image as 8-bit PNG when every id is in 0..255, else 16-bit; negative ids become 0.
void saveLabels(const std::string& path, const ImageI32& labels);
/// @brief Loads a label image (8- or 16-bit, single channel).
ImageI32 loadLabels(const std::string& path);
/// @brief Loads an 8-bit single-channel mask.
ImageU8 loadMask(const std::string& path);
/// @brief cv::imwrite that throws FileError naming the path when writing fails.
void writeImage(const std::string& path, const cv::Mat& image);

/// @brief True when the file exists and is a regular file.
bool fileExists(const std::string& path);

}  // namespace io
}  // namespace mc_flow
