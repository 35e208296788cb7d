#include "mc_flow/io/visualization.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "mc_flow/core/error.h"
#include "mc_flow/core/palette.h"

namespace mc_flow {
namespace io {
namespace {

// The Middlebury colour wheel: hue transitions red-yellow-green-cyan-blue-magenta-red with segment lengths
// chosen (by Baker et al.) to be roughly perceptually even. Entries are RGB in [0, 1].
const std::vector<std::array<float, 3>>& colourWheel() {
  static const std::vector<std::array<float, 3>> wheel = [] {
    const int RY = 15, YG = 6, GC = 4, CB = 11, BM = 13, MR = 6;
    std::vector<std::array<float, 3>> w;
    for (int i = 0; i < RY; ++i) w.push_back({1.f, std::floor(255.f * i / RY) / 255.f, 0.f});
    for (int i = 0; i < YG; ++i) w.push_back({1.f - std::floor(255.f * i / YG) / 255.f, 1.f, 0.f});
    for (int i = 0; i < GC; ++i) w.push_back({0.f, 1.f, std::floor(255.f * i / GC) / 255.f});
    for (int i = 0; i < CB; ++i) w.push_back({0.f, 1.f - std::floor(255.f * i / CB) / 255.f, 1.f});
    for (int i = 0; i < BM; ++i) w.push_back({std::floor(255.f * i / BM) / 255.f, 0.f, 1.f});
    for (int i = 0; i < MR; ++i) w.push_back({1.f, 0.f, 1.f - std::floor(255.f * i / MR) / 255.f});
    return w;
  }();
  return wheel;
}

cv::Vec3b flowColour(float u, float v) {
  const auto& wheel = colourWheel();
  const int n = int(wheel.size());
  const float radius = std::sqrt(u * u + v * v);
  const float angle = std::atan2(-v, -u) / float(M_PI);  // [-1, 1]
  const float fk = (angle + 1.f) / 2.f * float(n - 1);
  const int k0 = std::clamp(int(std::floor(fk)), 0, n - 1);
  const int k1 = (k0 + 1) % n;
  const float f = fk - float(k0);
  cv::Vec3b bgr;
  for (int c = 0; c < 3; ++c) {
    float col = (1.f - f) * wheel[k0][c] + f * wheel[k1][c];
    col = radius <= 1.f ? 1.f - radius * (1.f - col) : col * 0.75f;  // saturation grows with the magnitude
    bgr[2 - c] = cv::saturate_cast<std::uint8_t>(255.f * col);
  }
  return bgr;
}

}  // namespace

cv::Vec3b segmentColor(int id) {
  const Rgb8 c = colourForId(std::uint32_t(std::max(id, 0)));
  return {c.b, c.g, c.r};
}

cv::Mat intensityImage(const ImageF& intensity) {
  cv::Mat grey(intensity.height, intensity.width, CV_8UC1);
  for (int y = 0; y < intensity.height; ++y)
    for (int x = 0; x < intensity.width; ++x)
      grey.at<std::uint8_t>(y, x) = cv::saturate_cast<std::uint8_t>(255.f * intensity(x, y));
  cv::Mat bgr;
  cv::cvtColor(grey, bgr, cv::COLOR_GRAY2BGR);
  return bgr;
}

cv::Mat segmentationImage(const SoftLabels& labels, const std::vector<int>& ids, const ImageF& intensity) {
  if (!intensity.sameSize(labels.width, labels.height))
    throw InputError("segmentation picture: soft labels are " + std::to_string(labels.width) + "x" +
                     std::to_string(labels.height) + " but the image is " + std::to_string(intensity.width) + "x" +
                     std::to_string(intensity.height));
  const ImageU8 rgb = segmentationPicture(labels, ids, &intensity, 0.6);
  cv::Mat out(rgb.height, rgb.width, CV_8UC3);
  for (int y = 0; y < rgb.height; ++y)
    for (int x = 0; x < rgb.width; ++x) out.at<cv::Vec3b>(y, x) = cv::Vec3b(rgb(x, y, 2), rgb(x, y, 1), rgb(x, y, 0));
  return out;
}

cv::Mat flowColorImage(const ImageF& flow, double max_magnitude) {
  if (flow.channels != 2) throw InputError("flow picture: flow needs 2 channels, got " + std::to_string(flow.channels));
  if (!(max_magnitude > 0)) {
    // The largest magnitude after dropping the top 0.5 %: one diverged segment (a few pixels flying off by
    // hundreds of pixels) would otherwise wash every other colour out to white.
    std::vector<float> magnitudes;
    magnitudes.reserve(flow.pixelCount());
    for (std::size_t p = 0; p < flow.pixelCount(); ++p) {
      const float u = flow.data[2 * p], v = flow.data[2 * p + 1];
      if (std::isfinite(u) && std::isfinite(v)) magnitudes.push_back(std::hypot(u, v));
    }
    max_magnitude = 0;
    if (!magnitudes.empty()) {
      const std::size_t keep = magnitudes.size() - magnitudes.size() / 200;
      std::nth_element(magnitudes.begin(), magnitudes.begin() + (keep - 1), magnitudes.end());
      max_magnitude = magnitudes[keep - 1];
    }
  }
  const float scale = max_magnitude > 1e-9 ? float(1.0 / max_magnitude) : 0.f;
  cv::Mat out(flow.height, flow.width, CV_8UC3, cv::Scalar(0, 0, 0));
  for (int y = 0; y < flow.height; ++y)
    for (int x = 0; x < flow.width; ++x) {
      const float u = flow(x, y, 0), v = flow(x, y, 1);
      if (std::isfinite(u) && std::isfinite(v)) out.at<cv::Vec3b>(y, x) = flowColour(u * scale, v * scale);
    }
  return out;
}

cv::Mat depthColorImage(const ImageF& depth, double max_depth) {
  if (!(max_depth > 0)) {
    max_depth = 0;
    for (float z : depth.data)
      if (isValidDepth(z)) max_depth = std::max<double>(max_depth, z);
  }
  cv::Mat grey(depth.height, depth.width, CV_8UC1, cv::Scalar(0));
  cv::Mat valid(depth.height, depth.width, CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < depth.height; ++y)
    for (int x = 0; x < depth.width; ++x) {
      const float z = depth(x, y);
      if (!isValidDepth(z) || max_depth <= 0) continue;
      grey.at<std::uint8_t>(y, x) = cv::saturate_cast<std::uint8_t>(255.0 * z / max_depth);
      valid.at<std::uint8_t>(y, x) = 255;
    }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  cv::Mat out(depth.height, depth.width, CV_8UC3, cv::Scalar(0, 0, 0));
  colour.copyTo(out, valid);
  return out;
}

cv::Mat maskImage(const ImageU8& mask) {
  cv::Mat grey(mask.height, mask.width, CV_8UC1);
  for (int y = 0; y < mask.height; ++y)
    for (int x = 0; x < mask.width; ++x) grey.at<std::uint8_t>(y, x) = mask(x, y) ? 255 : 0;
  cv::Mat bgr;
  cv::cvtColor(grey, bgr, cv::COLOR_GRAY2BGR);
  return bgr;
}

cv::Mat overviewPanel(const std::vector<std::pair<std::string, cv::Mat>>& tiles, int columns) {
  if (tiles.empty() || columns <= 0) throw InputError("overview panel: no tiles or no columns");
  const cv::Size tile_size = tiles.front().second.size();
  const int rows = (int(tiles.size()) + columns - 1) / columns;
  cv::Mat panel(rows * tile_size.height, columns * tile_size.width, CV_8UC3, cv::Scalar(0, 0, 0));
  const double font_scale = std::max(0.35, 0.5 * tile_size.width / 320.0);
  const int thickness = font_scale > 0.8 ? 2 : 1;
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    cv::Mat tile = tiles[i].second;
    if (tile.channels() == 1) cv::cvtColor(tile, tile, cv::COLOR_GRAY2BGR);
    if (tile.size() != tile_size) cv::resize(tile, tile, tile_size, 0, 0, cv::INTER_NEAREST);
    const cv::Rect roi(int(i % columns) * tile_size.width, int(i / columns) * tile_size.height, tile_size.width,
                       tile_size.height);
    tile.copyTo(panel(roi));
    // Dark outline under white text keeps the caption readable over any content.
    const cv::Point origin(roi.x + 5, roi.y + int(18 * font_scale / 0.5));
    cv::putText(panel, tiles[i].first, origin, cv::FONT_HERSHEY_SIMPLEX, font_scale, cv::Scalar(0, 0, 0), thickness + 2,
                cv::LINE_AA);
    cv::putText(panel, tiles[i].first, origin, cv::FONT_HERSHEY_SIMPLEX, font_scale, cv::Scalar(255, 255, 255),
                thickness, cv::LINE_AA);
  }
  return panel;
}

}  // namespace io
}  // namespace mc_flow
