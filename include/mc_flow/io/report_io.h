/**
 * @file report_io.h
 * @brief JSON outputs: segments.json, report.json, eval.json, gt_segments.json (written with nlohmann/json,
 * two-space indentation, keys in the documented order). JSON has no NaN: non-finite numbers are written as null.
 */
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "mc_flow/core/config.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "mc_flow/io/flow_io.h"

namespace mc_flow {
namespace io {

/// @brief What the tool knows about a run beyond the solver's Result.
struct RunInfo {
  std::string rgb1, depth1, rgb2, depth2;  ///< input files ("" when the frames came from memory)
  double depth_scale = 1000.0;             ///< units per metre of 16-bit depth inputs
  double load_ms = 0, write_ms = 0;        ///< file reading / writing wall time [ms]
};

/// @brief Per-segment id, twist (vx vy vz [m], wx wy wz [rad]), 4x4 transform (row-major), support, centroid [m], the
/// twist's 6x6 covariance (row-major) and whether the segment is part of the static world (Result::world).
std::string segmentsJson(const Result& result);
/// @brief Resolution, processing resolution, intrinsics, every Config field, stage timings [ms],
/// per-outer-iteration statistics, final energy, backend, the static world (found, chosen_by, ids, twist, 6x6
/// covariance row-major, pixels).
std::string reportJson(const Result& result, const Config& config, const RunInfo& info);

/// @brief The numbers `mcflow eval` computes; fields whose `has_*` flag is false are written as null.
struct EvalMetrics {
  bool has_ground_truth = false;
  bool has_inputs = false;
  // optical flow vs ground truth, non-occluded pixels (ground-truth occlusion excluded)
  double flow_epe = 0, flow_aae_deg = 0;
  double flow_epe_zero_flow = 0;  ///< EPE of predicting no motion: the scale against which flow_epe is judged
  std::size_t flow_pixels = 0;
  // the same on moving pixels only (ground-truth flow >= 0.5 px): the static background does not dilute it
  double flow_epe_moving = 0, flow_epe_moving_zero_flow = 0;
  std::size_t moving_pixels = 0;
  // scene flow vs ground truth [m]
  double scene_flow_epe = 0, scene_flow_epe_zero_flow = 0;
  std::size_t scene_flow_pixels = 0;
  double segmentation_agreement = 0;  ///< gt_parts vs labels, best one-to-one matching
  double occlusion_agreement = 0;     ///< estimated vs ground-truth occlusion on pixels with a surface
  // Table 1: residuals after warping frame 2 back, estimated occlusions excluded
  double rmse_photometric = 0, rmse_geometric = 0;
  double rmse_photometric_zero_flow = 0, rmse_geometric_zero_flow = 0;
  std::size_t residual_pixels = 0;
  int segments = 0;  ///< distinct non-zero ids in labels.png
  /// With ground truth: per true part (gt_parts), its pixels and the id most of them carry in labels.png (0 when
  /// none has an id); comparing these over a sequence's pairs shows whether a part keeps its id.
  struct PartId {
    int part = 0;
    std::size_t pixels = 0;
    int majority_id = 0;
    double share = 0;  ///< fraction of the part's pixels that carry majority_id
  };
  std::vector<PartId> part_ids;
};
std::string evalJson(const EvalMetrics& metrics);
/// @brief Human-readable table of the metrics (what `mcflow eval` prints).
std::string evalTable(const EvalMetrics& metrics);

/// @brief Ground-truth parts of a synthetic pair: id, name, twist, transform.
std::string groundTruthSegmentsJson(const std::vector<SyntheticPart>& parts);

// writeTextFile, readTextFile: mc_flow/io/flow_io.h.
/// @brief Parses a JSON file (e.g. one of the outputs above; null stands for a missing or non-finite number).
/// Throws InputError naming the path and line when the file is missing or is not valid JSON.
/// Include <nlohmann/json.hpp> to use the returned value.
nlohmann::json readJsonFile(const std::string& path);

}  // namespace io
}  // namespace mc_flow
