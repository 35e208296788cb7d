/**
 * @file result_io.h
 * @brief The directories the `mcflow` tool reads and writes: a run's inputs, its outputs, a synthetic
 * pair with ground truth, and the evaluation of a result against ground truth and/or the inputs.
 */
#pragma once

#include <string>

#include "mc_flow/core/image.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "mc_flow/io/report_io.h"

namespace mc_flow {
namespace io {

/// @brief Paths of the four input images and how 16-bit depth is scaled.
struct PairPaths {
  std::string rgb1, depth1, rgb2, depth2;
  double depth_scale = 1000.0;  ///< 16-bit depth units per metre
};

/// @brief Two loaded frames plus their colour images (RGB 8-bit) for the pictures.
struct LoadedPair {
  RgbdFrame frame1, frame2;
  ImageU8 rgb1, rgb2;
};

/// @brief Loads both frames; throws InputError naming both files when any two sizes differ.
LoadedPair loadPair(const PairPaths& paths);

/// @brief Creates `dir` (and parents); throws FileError naming it when that fails or it is not writable.
void createOutputDirectory(const std::string& dir);

/// @brief Writes every output file of a run into `dir` (see the tool's help for the list).
void writeResultDirectory(const std::string& dir, const Result& result, const Config& config, const LoadedPair& pair,
                          const RunInfo& info);

/// @brief Writes a synthetic pair: rgb1/2.png, depth1/2.png (16-bit mm), depth1/2.pfm (float metres),
/// intrinsics.txt, camera_info.yaml, gt_optical_flow.flo, gt_scene_flow.pfm, gt_occlusion.png, gt_parts.png,
/// gt_segments.json.
void writeSyntheticDirectory(const std::string& dir, const SyntheticPair& pair);

/// @brief The input paths inside a synthetic directory (float .pfm depth when present, else the 16-bit PNG).
PairPaths syntheticPairPaths(const std::string& dir);

/// @brief The outputs of a run read back from its directory.
struct ResultFiles {
  ImageF optical_flow, scene_flow;
  ImageI32 labels;
  ImageU8 occlusion;
};
ResultFiles loadResultDirectory(const std::string& dir);

/// @brief Ground truth read from a synthetic directory.
struct GroundTruthFiles {
  ImageF optical_flow, scene_flow;
  ImageU8 occlusion;
  ImageI32 parts;
};
GroundTruthFiles loadGroundTruthDirectory(const std::string& dir);
/// @brief True when `dir` holds the ground-truth files that loadGroundTruthDirectory reads.
bool hasGroundTruth(const std::string& dir);

/// @brief Computes the metrics available from what is given: ground truth (may be null) and the inputs with
/// intrinsics (both null or both set). Throws InputError when sizes disagree.
EvalMetrics evaluateResult(const ResultFiles& result, const GroundTruthFiles* truth, const LoadedPair* inputs,
                           const Intrinsics* K);

}  // namespace io
}  // namespace mc_flow
