#include "mc_flow/io/report_io.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>

#include "mc_flow/core/error.h"
#include "mc_flow/io/image_io.h"

namespace mc_flow {
namespace io {
namespace {

std::string formatNumber(double v) {
  if (!std::isfinite(v)) return "null";
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.10g", v);
  return buffer;
}

std::vector<double> twistValues(const Vector6d& xi) { return {xi(0), xi(1), xi(2), xi(3), xi(4), xi(5)}; }

std::vector<double> transformValues(const Eigen::Matrix4d& T) {
  std::vector<double> v;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) v.push_back(T(r, c));
  return v;
}

}  // namespace

void JsonWriter::separate() {
  if (after_key_) {
    after_key_ = false;
    return;
  }
  if (!first_in_scope_.empty()) {
    if (!first_in_scope_.back()) out_ += ",";
    first_in_scope_.back() = false;
    out_ += "\n" + std::string(2 * first_in_scope_.size(), ' ');
  }
}

JsonWriter& JsonWriter::beginObject() {
  separate();
  out_ += "{";
  first_in_scope_.push_back(true);
  return *this;
}

JsonWriter& JsonWriter::endObject() {
  const bool empty = first_in_scope_.back();
  first_in_scope_.pop_back();
  if (!empty) out_ += "\n" + std::string(2 * first_in_scope_.size(), ' ');
  out_ += "}";
  if (first_in_scope_.empty()) out_ += "\n";
  return *this;
}

JsonWriter& JsonWriter::beginArray() {
  separate();
  out_ += "[";
  first_in_scope_.push_back(true);
  return *this;
}

JsonWriter& JsonWriter::endArray() {
  const bool empty = first_in_scope_.back();
  first_in_scope_.pop_back();
  if (!empty) out_ += "\n" + std::string(2 * first_in_scope_.size(), ' ');
  out_ += "]";
  return *this;
}

JsonWriter& JsonWriter::key(const std::string& name) {
  separate();
  out_ += jsonQuote(name) + ": ";
  after_key_ = true;
  return *this;
}

JsonWriter& JsonWriter::raw(const std::string& json) {
  separate();
  out_ += json;
  return *this;
}

JsonWriter& JsonWriter::value(double v) { return raw(formatNumber(v)); }
JsonWriter& JsonWriter::value(int v) { return raw(std::to_string(v)); }
JsonWriter& JsonWriter::value(long long v) { return raw(std::to_string(v)); }
JsonWriter& JsonWriter::value(std::size_t v) { return raw(std::to_string(v)); }
JsonWriter& JsonWriter::value(bool v) { return raw(v ? "true" : "false"); }
JsonWriter& JsonWriter::value(const std::string& v) { return raw(jsonQuote(v)); }
JsonWriter& JsonWriter::value(const char* v) { return raw(jsonQuote(v)); }

JsonWriter& JsonWriter::numbers(const std::vector<double>& values) {
  std::string line = "[";
  for (std::size_t i = 0; i < values.size(); ++i) line += (i ? ", " : "") + formatNumber(values[i]);
  return raw(line + "]");
}

std::string jsonQuote(const std::string& text) {
  std::string out = "\"";
  for (unsigned char c : text) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default:
        if (c < 0x20) {
          char buffer[8];
          std::snprintf(buffer, sizeof(buffer), "\\u%04x", c);
          out += buffer;
        } else {
          out.push_back(char(c));
        }
    }
  }
  return out + "\"";
}

std::string configValueToJson(const std::string& text) {
  if (text == "true" || text == "false") return text;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (!text.empty() && end && *end == '\0' && std::isfinite(v)) return formatNumber(v);
  return jsonQuote(text);
}

std::string segmentsJson(const Result& result) {
  JsonWriter w;
  w.beginObject();
  w.key("frame").value("camera optical frame of frame 1 (x right, y down, z forward); transform maps frame-1 "
                       "points to their frame-2 positions");
  w.key("units").value("twist: v [m], w [rad] over the frame interval; centroid [m]; support [pixels]");
  w.key("segments").beginArray();
  for (const Segment& s : result.segments) {
    w.beginObject();
    w.key("id").value(s.id);
    w.key("twist").numbers(twistValues(s.twist));
    w.key("transform").numbers(transformValues(s.transform));
    w.key("support").value(s.support);
    w.key("centroid").numbers({s.centroid.x(), s.centroid.y(), s.centroid.z()});
    w.key("speed").value(s.twist.head<3>().norm());
    w.key("rotation_angle").value(s.twist.tail<3>().norm());
    w.endObject();
  }
  w.endArray();
  w.endObject();
  return w.str();
}

std::string reportJson(const Result& result, const Config& config, const RunInfo& info) {
  JsonWriter w;
  w.beginObject();
  w.key("inputs").beginObject();
  w.key("rgb1").value(info.rgb1).key("depth1").value(info.depth1);
  w.key("rgb2").value(info.rgb2).key("depth2").value(info.depth2);
  w.key("depth_scale").value(info.depth_scale);
  w.endObject();
  w.key("resolution").beginObject().key("width").value(result.width).key("height").value(result.height).endObject();
  w.key("processing_resolution")
      .beginObject()
      .key("width")
      .value(result.processing_width)
      .key("height")
      .value(result.processing_height)
      .endObject();
  w.key("pyramid_levels").value(result.pyramid_levels);
  const Intrinsics& K = result.intrinsics;
  w.key("intrinsics").beginObject().key("fx").value(K.fx).key("fy").value(K.fy).key("cx").value(K.cx).key("cy").value(K.cy).endObject();
  w.key("config").beginObject();
  for (const auto& [name, value] : config.fields()) w.key(name).raw(configValueToJson(value));
  w.endObject();
  w.key("backend").value(result.backend);
  w.key("backend_note").value(result.backend_note);
  const StageTimings& t = result.timings;
  w.key("timings_ms").beginObject();
  w.key("load").value(info.load_ms);
  w.key("preprocessing").value(t.preprocessing);
  w.key("initialisation").value(t.initialisation);
  w.key("motion").value(t.motion);
  w.key("labels").value(t.labels);
  w.key("adaptation").value(t.adaptation);
  w.key("occlusion").value(t.occlusion);
  w.key("outputs").value(t.outputs);
  w.key("solver_total").value(t.total);
  w.key("write").value(info.write_ms);
  w.endObject();
  w.key("iterations").beginArray();
  for (const OuterIterationStats& it : result.iterations) {
    w.beginObject();
    w.key("iteration").value(it.iteration);
    w.key("labels_before").value(it.labels_before);
    w.key("labels_after").value(it.labels_after);
    w.key("merged").value(it.merged);
    w.key("removed").value(it.removed);
    w.key("motion_iterations").value(it.motion_iterations);
    w.key("label_iterations").value(it.label_iterations);
    w.key("label_change").value(it.label_change);
    w.key("energy").value(it.energy);
    w.endObject();
  }
  w.endArray();
  w.key("final_energy").value(result.energy);
  w.key("segments").value(int(result.segments.size()));
  w.endObject();
  return w.str();
}

std::string evalJson(const EvalMetrics& m) {
  JsonWriter w;
  const double nan = std::nan("");
  const bool gt = m.has_ground_truth, in = m.has_inputs;
  w.beginObject();
  w.key("has_ground_truth").value(gt);
  w.key("has_inputs").value(in);
  w.key("segments").value(m.segments);
  w.key("optical_flow_epe_px").value(gt ? m.flow_epe : nan);
  w.key("optical_flow_aae_deg").value(gt ? m.flow_aae_deg : nan);
  w.key("optical_flow_epe_zero_flow_px").value(gt ? m.flow_epe_zero_flow : nan);
  w.key("optical_flow_pixels").value(m.flow_pixels);
  w.key("optical_flow_epe_moving_px").value(gt ? m.flow_epe_moving : nan);
  w.key("optical_flow_epe_moving_zero_flow_px").value(gt ? m.flow_epe_moving_zero_flow : nan);
  w.key("moving_pixels").value(m.moving_pixels);
  w.key("scene_flow_epe_m").value(gt ? m.scene_flow_epe : nan);
  w.key("scene_flow_epe_zero_flow_m").value(gt ? m.scene_flow_epe_zero_flow : nan);
  w.key("scene_flow_pixels").value(m.scene_flow_pixels);
  w.key("segmentation_agreement").value(gt ? m.segmentation_agreement : nan);
  w.key("occlusion_agreement").value(gt ? m.occlusion_agreement : nan);
  w.key("rmse_photometric").value(in ? m.rmse_photometric : nan);
  w.key("rmse_geometric_m").value(in ? m.rmse_geometric : nan);
  w.key("rmse_photometric_zero_flow").value(in ? m.rmse_photometric_zero_flow : nan);
  w.key("rmse_geometric_zero_flow_m").value(in ? m.rmse_geometric_zero_flow : nan);
  w.key("residual_pixels").value(m.residual_pixels);
  w.endObject();
  return w.str();
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
  JsonWriter w;
  w.beginObject();
  w.key("units").value("twist: v [m], w [rad] over the frame interval, frame-1 camera frame");
  w.key("parts").beginArray();
  for (const SyntheticPart& p : parts) {
    w.beginObject();
    w.key("id").value(p.id);
    w.key("name").value(p.name);
    w.key("twist").numbers(twistValues(p.twist));
    w.key("transform").numbers(transformValues(se3Exp(p.twist)));
    w.endObject();
  }
  w.endArray();
  w.endObject();
  return w.str();
}

void writeTextFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw FileError("cannot create '" + path + "'");
  out << text;
  out.flush();
  if (!out) throw FileError("error while writing '" + path + "'");
}

std::string readTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError("cannot open '" + path + "' for reading (missing or unreadable)");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace io
}  // namespace mc_flow
