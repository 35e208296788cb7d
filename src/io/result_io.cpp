#include "mc_flow/io/result_io.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/io/camera_info.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/visualization.h"

namespace mc_flow {
namespace io {
namespace {

namespace fs = std::filesystem;

constexpr double kMovingFlowPx = 0.5;  // ground-truth flow at least this long counts as moving

std::string join(const std::string& dir, const std::string& name) { return (fs::path(dir) / name).string(); }

template <typename A, typename B>
void requireSameSize(const A& a, const std::string& a_name, const B& b, const std::string& b_name) {
  if (!a.sameSize(b))
    throw InputError("image size mismatch: " + a_name + " is " + imageSizeText(a.width, a.height) + " but " + b_name +
                     " is " + imageSizeText(b.width, b.height));
}

// Copy of `image` (any channel count) with every channel NaN where `reference` has a non-finite value.
ImageF zeroLike(const ImageF& reference) {
  ImageF zero(reference.width, reference.height, reference.channels, 0.f);
  for (std::size_t p = 0; p < reference.pixelCount(); ++p)
    for (int c = 0; c < reference.channels; ++c)
      if (!std::isfinite(reference.data[p * reference.channels + c]))
        for (int k = 0; k < reference.channels; ++k) zero.data[p * reference.channels + k] = std::nanf("");
  return zero;
}

bool finitePixel(const ImageF& image, std::size_t p) {
  for (int c = 0; c < image.channels; ++c)
    if (!std::isfinite(image.data[p * image.channels + c])) return false;
  return true;
}

}  // namespace

LoadedPair loadPair(const PairPaths& paths) {
  LoadedPair pair;
  pair.frame1 = loadRgbdFrame(paths.rgb1, paths.depth1, paths.depth_scale, &pair.rgb1);
  pair.frame2 = loadRgbdFrame(paths.rgb2, paths.depth2, paths.depth_scale, &pair.rgb2);
  requireSameSize(pair.frame1.intensity, "rgb1 '" + paths.rgb1 + "'", pair.frame2.intensity,
                  "rgb2 '" + paths.rgb2 + "'");
  return pair;
}

void createOutputDirectory(const std::string& dir) {
  if (dir.empty()) throw FileError("output directory: empty path");
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw FileError("cannot create output directory '" + dir + "': " + ec.message());
  if (!fs::is_directory(dir, ec)) throw FileError("output path '" + dir + "' exists and is not a directory");
  // Probe writability now, before the (possibly long) solve.
  const std::string probe = join(dir, ".mcflow_write_probe");
  try {
    writeTextFile(probe, "");
  } catch (const FileError&) {
    throw FileError("output directory '" + dir + "' is not writable");
  }
  fs::remove(probe, ec);
}

void writeResultDirectory(const std::string& dir, const Result& result, const Config& config, const LoadedPair& pair,
                          const RunInfo& info) {
  const auto start = std::chrono::steady_clock::now();
  createOutputDirectory(dir);
  writeFlo(join(dir, "optical_flow.flo"), result.optical_flow);
  writePfm(join(dir, "scene_flow.pfm"), result.scene_flow);
  saveLabels(join(dir, "labels.png"), result.labels);
  writeSoftLabelsNpy(join(dir, "soft_labels.npy"), result.soft_labels);
  saveMask(join(dir, "occlusion.png"), result.occlusion);
  writeTextFile(join(dir, "segments.json"), segmentsJson(result));

  std::vector<int> ids;
  for (const Segment& segment : result.segments) ids.push_back(segment.id);
  const cv::Mat segmentation = segmentationImage(result.soft_labels, ids, pair.frame1.intensity);
  const cv::Mat flow = flowColorImage(result.optical_flow);
  writeImage(join(dir, "segmentation.png"), segmentation);
  writeImage(join(dir, "flow.png"), flow);
  cv::Mat rgb1 = toMat(pair.rgb1), rgb2 = toMat(pair.rgb2);
  cv::cvtColor(rgb1, rgb1, cv::COLOR_RGB2BGR);
  cv::cvtColor(rgb2, rgb2, cv::COLOR_RGB2BGR);
  const cv::Mat panel = overviewPanel({{"rgb1", rgb1},
                                       {"rgb2", rgb2},
                                       {"depth1", depthColorImage(pair.frame1.depth, config.max_depth)},
                                       {"segmentation (" + std::to_string(result.segments.size()) + ")", segmentation},
                                       {"optical flow", flow},
                                       {"occlusion", maskImage(result.occlusion)}},
                                      3);
  writeImage(join(dir, "overview.png"), panel);

  RunInfo timed = info;
  timed.write_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  writeTextFile(join(dir, "report.json"), reportJson(result, config, timed));
}

void writeSyntheticDirectory(const std::string& dir, const SyntheticPair& pair) {
  createOutputDirectory(dir);
  saveRgb(join(dir, "rgb1.png"), pair.color1);
  saveRgb(join(dir, "rgb2.png"), pair.color2);
  saveDepthPng16(join(dir, "depth1.png"), pair.frame1.depth, 1000.0);
  saveDepthPng16(join(dir, "depth2.png"), pair.frame2.depth, 1000.0);
  writePfm(join(dir, "depth1.pfm"), pair.frame1.depth);
  writePfm(join(dir, "depth2.pfm"), pair.frame2.depth);
  writeTextFile(join(dir, "intrinsics.txt"), formatIntrinsics(pair.intrinsics) + "\n");
  saveCameraInfo(join(dir, "camera_info.yaml"), {pair.intrinsics, pair.frame1.width(), pair.frame1.height()});
  writeFlo(join(dir, "gt_optical_flow.flo"), pair.gt_optical_flow);
  writePfm(join(dir, "gt_scene_flow.pfm"), pair.gt_scene_flow);
  saveMask(join(dir, "gt_occlusion.png"), pair.gt_occlusion);
  saveLabels(join(dir, "gt_parts.png"), pair.gt_parts);
  writeTextFile(join(dir, "gt_segments.json"), groundTruthSegmentsJson(pair.parts));
  writeImage(join(dir, "gt_flow.png"), flowColorImage(pair.gt_optical_flow));
}

PairPaths syntheticPairPaths(const std::string& dir) {
  PairPaths paths;
  paths.rgb1 = join(dir, "rgb1.png");
  paths.rgb2 = join(dir, "rgb2.png");
  const bool exact = fileExists(join(dir, "depth1.pfm")) && fileExists(join(dir, "depth2.pfm"));
  paths.depth1 = join(dir, exact ? "depth1.pfm" : "depth1.png");
  paths.depth2 = join(dir, exact ? "depth2.pfm" : "depth2.png");
  paths.depth_scale = 1000.0;
  return paths;
}

ResultFiles loadResultDirectory(const std::string& dir) {
  for (const char* name : {"optical_flow.flo", "scene_flow.pfm", "labels.png", "occlusion.png"})
    if (!fileExists(join(dir, name)))
      throw InputError("result directory '" + dir + "': missing '" + name + "' (run `mcflow run --out " + dir +
                       "` first)");
  ResultFiles r;
  r.optical_flow = readFlo(join(dir, "optical_flow.flo"));
  r.scene_flow = readPfm(join(dir, "scene_flow.pfm"));
  r.labels = loadLabels(join(dir, "labels.png"));
  r.occlusion = loadMask(join(dir, "occlusion.png"));
  requireSameSize(r.optical_flow, "optical_flow.flo", r.scene_flow, "scene_flow.pfm");
  requireSameSize(r.optical_flow, "optical_flow.flo", r.labels, "labels.png");
  requireSameSize(r.optical_flow, "optical_flow.flo", r.occlusion, "occlusion.png");
  if (r.scene_flow.channels != 3) throw InputError("'" + join(dir, "scene_flow.pfm") + "': expected 3 channels");
  return r;
}

bool hasGroundTruth(const std::string& dir) {
  for (const char* name : {"gt_optical_flow.flo", "gt_scene_flow.pfm", "gt_occlusion.png", "gt_parts.png"})
    if (!fileExists(join(dir, name))) return false;
  return true;
}

GroundTruthFiles loadGroundTruthDirectory(const std::string& dir) {
  for (const char* name : {"gt_optical_flow.flo", "gt_scene_flow.pfm", "gt_occlusion.png", "gt_parts.png"})
    if (!fileExists(join(dir, name))) throw InputError("ground-truth directory '" + dir + "': missing '" + name + "'");
  GroundTruthFiles gt;
  gt.optical_flow = readFlo(join(dir, "gt_optical_flow.flo"));
  gt.scene_flow = readPfm(join(dir, "gt_scene_flow.pfm"));
  gt.occlusion = loadMask(join(dir, "gt_occlusion.png"));
  gt.parts = loadLabels(join(dir, "gt_parts.png"));
  return gt;
}

EvalMetrics evaluateResult(const ResultFiles& result, const GroundTruthFiles* truth, const LoadedPair* inputs,
                           const Intrinsics* K) {
  EvalMetrics m;
  std::set<int> ids;
  for (std::int32_t id : result.labels.data)
    if (id > 0) ids.insert(id);
  m.segments = int(ids.size());

  if (truth) {
    m.has_ground_truth = true;
    requireSameSize(result.optical_flow, "result optical_flow.flo", truth->optical_flow, "gt_optical_flow.flo");
    requireSameSize(result.optical_flow, "result optical_flow.flo", truth->occlusion, "gt_occlusion.png");
    requireSameSize(result.optical_flow, "result optical_flow.flo", truth->parts, "gt_parts.png");
    requireSameSize(result.optical_flow, "result optical_flow.flo", truth->scene_flow, "gt_scene_flow.pfm");
    const FlowErrors flow = opticalFlowErrors(result.optical_flow, truth->optical_flow, &truth->occlusion);
    const FlowErrors zero = opticalFlowErrors(zeroLike(result.optical_flow), truth->optical_flow, &truth->occlusion);
    m.flow_epe = flow.epe;
    m.flow_aae_deg = flow.aae_deg;
    m.flow_pixels = flow.pixels;
    m.flow_epe_zero_flow = zero.epe;
    ImageU8 static_or_occluded = truth->occlusion;
    for (std::size_t p = 0; p < static_or_occluded.pixelCount(); ++p) {
      const float u = truth->optical_flow.data[2 * p], v = truth->optical_flow.data[2 * p + 1];
      if (!(std::hypot(u, v) >= kMovingFlowPx)) static_or_occluded.data[p] = 255;
    }
    const FlowErrors moving = opticalFlowErrors(result.optical_flow, truth->optical_flow, &static_or_occluded);
    m.flow_epe_moving = moving.epe;
    m.moving_pixels = moving.pixels;
    m.flow_epe_moving_zero_flow =
        opticalFlowErrors(zeroLike(result.optical_flow), truth->optical_flow, &static_or_occluded).epe;
    m.scene_flow_epe = sceneFlowEpe(result.scene_flow, truth->scene_flow, &truth->occlusion, &m.scene_flow_pixels);
    m.scene_flow_epe_zero_flow = sceneFlowEpe(zeroLike(result.scene_flow), truth->scene_flow, &truth->occlusion);

    // Pixels without a surface in either image take no part in the segmentation/occlusion comparison.
    ImageI32 labels = result.labels;
    ImageU8 valid(labels.width, labels.height, 1, 0);
    for (std::size_t p = 0; p < labels.pixelCount(); ++p) {
      const bool both = finitePixel(result.optical_flow, p) && finitePixel(truth->optical_flow, p);
      if (!both) labels.data[p] = -1;
      valid.data[p] = both ? 255 : 0;
    }
    m.segmentation_agreement = segmentationAgreement(labels, truth->parts);
    // Each true part's majority id, over all its pixels (as mcflow_bench_stream judges id consistency).
    std::map<int, std::map<int, std::size_t>> votes;
    std::map<int, std::size_t> part_pixels;
    for (std::size_t p = 0; p < truth->parts.pixelCount(); ++p) {
      const int part = truth->parts.data[p];
      if (part < 0) continue;
      ++part_pixels[part];
      if (result.labels.data[p] > 0) ++votes[part][result.labels.data[p]];
    }
    for (const auto& [part, pixels] : part_pixels) {
      EvalMetrics::PartId entry;
      entry.part = part;
      entry.pixels = pixels;
      std::size_t best = 0;
      for (const auto& [id, n] : votes[part])
        if (n > best) best = n, entry.majority_id = id;
      entry.share = double(best) / double(pixels);
      m.part_ids.push_back(entry);
    }
    m.occlusion_agreement = maskAgreement(result.occlusion, truth->occlusion, &valid);
  }

  if (inputs && K) {
    m.has_inputs = true;
    requireSameSize(result.scene_flow, "result scene_flow.pfm", inputs->frame1.intensity, "input frame 1");
    const ResidualRmse est =
        warpResidualRmse(inputs->frame1, inputs->frame2, *K, &result.scene_flow, &result.occlusion);
    const ResidualRmse zero = warpResidualRmse(inputs->frame1, inputs->frame2, *K, nullptr, &result.occlusion);
    m.rmse_photometric = est.photometric;
    m.rmse_geometric = est.geometric;
    m.residual_pixels = est.pixels;
    m.rmse_photometric_zero_flow = zero.photometric;
    m.rmse_geometric_zero_flow = zero.geometric;
  }
  return m;
}

}  // namespace io
}  // namespace mc_flow
