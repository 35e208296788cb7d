/**
 * @file report_io.h
 * @brief JSON outputs: segments.json, report.json, eval.json, gt_segments.json (small hand-written writer:
 * the files are flat enough that a JSON library would add a dependency for nothing).
 */
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/core/synthetic_scene.h"

namespace mc_flow {
namespace io {

/// @brief Streaming JSON writer with two-space indentation. Non-finite numbers are written as null.
class JsonWriter {
 public:
  JsonWriter& beginObject();
  JsonWriter& endObject();
  JsonWriter& beginArray();
  JsonWriter& endArray();
  JsonWriter& key(const std::string& name);
  JsonWriter& value(double v);
  JsonWriter& value(int v);
  JsonWriter& value(long long v);
  JsonWriter& value(std::size_t v);
  JsonWriter& value(bool v);
  JsonWriter& value(const std::string& v);
  JsonWriter& value(const char* v);
  /// @brief Writes text that is already valid JSON (e.g. a number from Config::fields()).
  JsonWriter& raw(const std::string& json);
  /// @brief An array of numbers on one line.
  JsonWriter& numbers(const std::vector<double>& values);
  const std::string& str() const { return out_; }

 private:
  void separate();
  std::string out_;
  std::vector<bool> first_in_scope_;
  bool after_key_ = false;
};

/// @brief JSON string literal (quotes included) of `text`.
std::string jsonQuote(const std::string& text);
/// @brief A Config::fields() value as JSON: numbers and booleans bare, anything else quoted.
std::string configValueToJson(const std::string& text);

/// @brief What the tool knows about a run beyond the solver's Result.
struct RunInfo {
  std::string rgb1, depth1, rgb2, depth2;  ///< input files ("" when the frames came from memory)
  double depth_scale = 1000.0;             ///< units per metre of 16-bit depth inputs
  double load_ms = 0, write_ms = 0;        ///< file reading / writing wall time [ms]
};

/// @brief Per-segment id, twist (vx vy vz [m], wx wy wz [rad]), 4x4 transform (row-major), support, centroid [m].
std::string segmentsJson(const Result& result);
/// @brief Resolution, processing resolution, intrinsics, every Config field, stage timings [ms],
/// per-outer-iteration statistics, final energy, backend.
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
};
std::string evalJson(const EvalMetrics& metrics);
/// @brief Human-readable table of the metrics (what `mcflow eval` prints).
std::string evalTable(const EvalMetrics& metrics);

/// @brief Ground-truth parts of a synthetic pair: id, name, twist, transform.
std::string groundTruthSegmentsJson(const std::vector<SyntheticPart>& parts);

/// @brief Writes `text` to `path`; throws FileError naming the path.
void writeTextFile(const std::string& path, const std::string& text);
/// @brief Reads a whole file; throws InputError naming the path.
std::string readTextFile(const std::string& path);

}  // namespace io
}  // namespace mc_flow
