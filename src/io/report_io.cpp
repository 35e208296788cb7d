#include "mc_flow/io/report_io.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include <nlohmann/json.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/io/image_io.h"

namespace mc_flow {
namespace io {
namespace {

// ordered_json keeps the keys in the order written, so the files read top-down like the documentation.
using Json = nlohmann::ordered_json;

// Non-finite numbers become null: JSON has no NaN or infinity.
Json number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

Json numbers(const std::vector<double>& values) {
  Json list = Json::array();
  for (double v : values) list.push_back(number(v));
  return list;
}

std::vector<double> twistValues(const Vector6d& xi) { return {xi(0), xi(1), xi(2), xi(3), xi(4), xi(5)}; }

// A matrix's entries row by row (a 4x4 transform, a 6x6 covariance).
template <typename Matrix>
std::vector<double> rowMajorValues(const Matrix& m) {
  std::vector<double> v;
  for (Eigen::Index r = 0; r < m.rows(); ++r)
    for (Eigen::Index c = 0; c < m.cols(); ++c) v.push_back(m(r, c));
  return v;
}

// A Config::fields() value (text) as JSON: booleans and numbers bare, enumerations as strings.
Json configValue(const std::string& text) {
  if (text == "true" || text == "false") return text == "true";
  if (text.empty()) return text;
  char* end = nullptr;
  const long long integer = std::strtoll(text.c_str(), &end, 10);
  if (*end == '\0') return integer;
  const double real = std::strtod(text.c_str(), &end);
  if (*end == '\0' && std::isfinite(real)) return real;
  return text;
}

std::string dump(const Json& json) { return json.dump(2) + "\n"; }

}  // namespace

std::string segmentsJson(const Result& result) {
  Json segments = Json::array();
  for (const Segment& s : result.segments)
    segments.push_back({{"id", s.id},
                        {"twist", numbers(twistValues(s.twist))},
                        {"transform", numbers(rowMajorValues(s.transform))},
                        {"support", s.support},
                        {"centroid", numbers({s.centroid.x(), s.centroid.y(), s.centroid.z()})},
                        {"speed", number(s.twist.head<3>().norm())},
                        {"rotation_angle", number(s.twist.tail<3>().norm())},
                        {"covariance", numbers(rowMajorValues(s.covariance))},
                        {"world", result.world.contains(s.id)}});
  return dump({{"frame",
                "camera optical frame of frame 1 (x right, y down, z forward); transform maps frame-1 "
                "points to their frame-2 positions"},
               {"units",
                "twist: v [m], w [rad] over the frame interval; covariance: of the twist, 6x6 row-major [m^2, m rad, "
                "rad^2]; centroid [m]; support [pixels]; world: the segment is part of the static world"},
               {"segments", segments}});
}

std::string reportJson(const Result& result, const Config& config, const RunInfo& info) {
  const Intrinsics& K = result.intrinsics;
  const StageTimings& t = result.timings;
  Json config_fields = Json::object();
  for (const auto& [name, value] : config.fields()) config_fields[name] = configValue(value);
  Json iterations = Json::array();
  for (const OuterIterationStats& it : result.iterations) {
    Json motion_levels = Json::array();
    for (const MotionLevelStats& m : it.motion_levels)
      motion_levels.push_back({{"level", m.level},
                               {"iterations", m.iterations},
                               {"stop", toString(m.stop)},
                               {"pixels", m.pixels_used},
                               {"cost_before", number(m.cost_before)},
                               {"cost_after", number(m.cost_after)},
                               {"largest_coupled_labels", m.largest_block},
                               {"accumulate_ms", number(m.accumulate_ms)},
                               {"solve_ms", number(m.solve_ms)}});
    iterations.push_back({{"iteration", it.iteration},
                          {"labels_before", it.labels_before},
                          {"labels_after", it.labels_after},
                          {"merged", it.merged},
                          {"removed", it.removed},
                          {"split", it.split},
                          {"merge_rounds", it.merge_rounds},
                          {"merge_pairs_tested", it.merge_pairs_tested},
                          {"motion_iterations", it.motion_iterations},
                          {"motion_levels", motion_levels},
                          {"label_iterations", it.label_iterations},
                          {"label_change", number(it.label_change)},
                          {"energy", number(it.energy)}});
  }
  Json report;
  report["inputs"] = {{"rgb1", info.rgb1},
                      {"depth1", info.depth1},
                      {"rgb2", info.rgb2},
                      {"depth2", info.depth2},
                      {"depth_scale", number(info.depth_scale)}};
  report["resolution"] = {{"width", result.width}, {"height", result.height}};
  report["processing_resolution"] = {{"width", result.processing_width}, {"height", result.processing_height}};
  report["pyramid_levels"] = result.pyramid_levels;
  report["intrinsics"] = {{"fx", number(K.fx)}, {"fy", number(K.fy)}, {"cx", number(K.cx)}, {"cy", number(K.cy)}};
  report["config"] = config_fields;
  report["backend"] = result.backend;
  report["backend_note"] = result.backend_note;
  report["timings_ms"] = {{"load", number(info.load_ms)},
                          {"preprocessing", number(t.preprocessing)},
                          {"initialisation", number(t.initialisation)},
                          {"motion", number(t.motion)},
                          {"labels", number(t.labels)},
                          {"adaptation", number(t.adaptation)},
                          {"merge_test", number(t.merge_test)},
                          {"occlusion", number(t.occlusion)},
                          {"outputs", number(t.outputs)},
                          {"solver_total", number(t.total)},
                          {"write", number(info.write_ms)}};
  report["iterations"] = iterations;
  report["final_energy"] = number(result.energy);
  report["segments"] = int(result.segments.size());
  // The static world: which segments, why, and its motion (the camera moved by the inverse).
  const StaticWorld& w = result.world;
  report["static_world"] = {{"found", w.found},
                            {"chosen_by", w.chosen_by},
                            {"ids", w.ids},
                            {"twist", numbers(twistValues(w.twist))},
                            {"covariance", numbers(rowMajorValues(w.covariance))},
                            {"pixels", number(w.pixels)}};
  return dump(report);
}

std::string evalJson(const EvalMetrics& m) {
  const bool gt = m.has_ground_truth, in = m.has_inputs;
  // Metrics whose source is missing are null rather than a misleading 0.
  auto ifGt = [&](double v) { return gt ? number(v) : Json(nullptr); };
  auto ifInputs = [&](double v) { return in ? number(v) : Json(nullptr); };
  Json part_ids = gt ? Json::array() : Json(nullptr);
  for (const EvalMetrics::PartId& p : m.part_ids)
    part_ids.push_back(
        {{"part", p.part}, {"pixels", p.pixels}, {"majority_id", p.majority_id}, {"share", number(p.share)}});
  return dump({{"has_ground_truth", gt},
               {"has_inputs", in},
               {"segments", m.segments},
               {"optical_flow_epe_px", ifGt(m.flow_epe)},
               {"optical_flow_aae_deg", ifGt(m.flow_aae_deg)},
               {"optical_flow_epe_zero_flow_px", ifGt(m.flow_epe_zero_flow)},
               {"optical_flow_pixels", m.flow_pixels},
               {"optical_flow_epe_moving_px", ifGt(m.flow_epe_moving)},
               {"optical_flow_epe_moving_zero_flow_px", ifGt(m.flow_epe_moving_zero_flow)},
               {"moving_pixels", m.moving_pixels},
               {"scene_flow_epe_m", ifGt(m.scene_flow_epe)},
               {"scene_flow_epe_zero_flow_m", ifGt(m.scene_flow_epe_zero_flow)},
               {"scene_flow_pixels", m.scene_flow_pixels},
               {"segmentation_agreement", ifGt(m.segmentation_agreement)},
               {"occlusion_agreement", ifGt(m.occlusion_agreement)},
               {"rmse_photometric", ifInputs(m.rmse_photometric)},
               {"rmse_geometric_m", ifInputs(m.rmse_geometric)},
               {"rmse_photometric_zero_flow", ifInputs(m.rmse_photometric_zero_flow)},
               {"rmse_geometric_zero_flow_m", ifInputs(m.rmse_geometric_zero_flow)},
               {"residual_pixels", m.residual_pixels},
               {"part_ids", part_ids}});
}

std::string evalTable(const EvalMetrics& m) {
  std::ostringstream out;
  char line[160];
  auto row = [&](const char* name, double value, const char* unit, double baseline) {
    std::snprintf(line, sizeof(line), "  %-28s %12.5f %-6s (zero flow: %.5f)\n", name, value, unit, baseline);
    out << line;
  };
  out << "metric                              estimate\n";
  std::snprintf(line, sizeof(line), "  %-28s %12d\n", "segments", m.segments);
  out << line;
  if (m.has_ground_truth) {
    row("optical flow EPE", m.flow_epe, "px", m.flow_epe_zero_flow);
    std::snprintf(line, sizeof(line), "  %-28s %12.5f %-6s\n", "optical flow AAE", m.flow_aae_deg, "deg");
    out << line;
    row("optical flow EPE (moving)", m.flow_epe_moving, "px", m.flow_epe_moving_zero_flow);
    row("scene flow EPE (3D)", m.scene_flow_epe, "m", m.scene_flow_epe_zero_flow);
    std::snprintf(line, sizeof(line), "  %-28s %12.5f\n  %-28s %12.5f\n", "segmentation agreement",
                  m.segmentation_agreement, "occlusion agreement", m.occlusion_agreement);
    out << line;
    std::snprintf(line, sizeof(line), "  (flow errors over %zu non-occluded pixels, %zu of them moving >= 0.5 px)\n",
                  m.flow_pixels, m.moving_pixels);
    out << line;
  }
  if (m.has_inputs) {
    row("RMSE photometric", m.rmse_photometric, "", m.rmse_photometric_zero_flow);
    row("RMSE geometric", m.rmse_geometric, "m", m.rmse_geometric_zero_flow);
    std::snprintf(line, sizeof(line), "  (residuals over %zu valid, non-occluded pixels)\n", m.residual_pixels);
    out << line;
  }
  return out.str();
}

std::string groundTruthSegmentsJson(const std::vector<SyntheticPart>& parts) {
  Json list = Json::array();
  for (const SyntheticPart& p : parts)
    list.push_back({{"id", p.id},
                    {"name", p.name},
                    {"twist", numbers(twistValues(p.twist))},
                    {"transform", numbers(rowMajorValues(se3Exp(p.twist)))}});
  return dump({{"units", "twist: v [m], w [rad] over the frame interval, frame-1 camera frame"}, {"parts", list}});
}

nlohmann::json readJsonFile(const std::string& path) {
  const std::string text = readTextFile(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    // e.byte is 1-based; the line is what a person looks for.
    const std::size_t at = std::min<std::size_t>(e.byte ? e.byte - 1 : 0, text.size());
    const auto line = 1 + std::count(text.begin(), text.begin() + std::ptrdiff_t(at), '\n');
    throw InputError("JSON file '" + path + "', line " + std::to_string(line) + ": " + e.what());
  }
}

}  // namespace io
}  // namespace mc_flow
