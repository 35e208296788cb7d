// Segment display colours (golden-ratio hue steps).
#include "mc_flow/core/palette.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "mc_flow/core/error.h"

namespace mc_flow {

namespace {

Rgb8 hsvToRgb(double hue, double saturation, double value) {
  const double h = std::fmod(hue, 1.0) * 6.0;
  const int sector = int(h) % 6;
  const double f = h - std::floor(h);
  const double p = value * (1 - saturation), q = value * (1 - saturation * f), t = value * (1 - saturation * (1 - f));
  double r = 0, g = 0, b = 0;
  switch (sector) {
    case 0:
      r = value;
      g = t;
      b = p;
      break;
    case 1:
      r = q;
      g = value;
      b = p;
      break;
    case 2:
      r = p;
      g = value;
      b = t;
      break;
    case 3:
      r = p;
      g = q;
      b = value;
      break;
    case 4:
      r = t;
      g = p;
      b = value;
      break;
    default:
      r = value;
      g = p;
      b = q;
      break;
  }
  auto to8 = [](double v) { return std::uint8_t(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); };
  return {to8(r), to8(g), to8(b)};
}

}  // namespace

Rgb8 colourForId(std::uint32_t id) {
  if (id == 0) return {60, 60, 60};
  // Golden-ratio hue steps keep consecutive ids far apart on the colour wheel; two brightness levels
  // separate ids whose hues end up close.
  const double golden = 0.6180339887498949;
  const double hue = std::fmod(0.11 + golden * id, 1.0);
  const double value = (id % 2 == 0) ? 0.80 : 0.98;
  const double saturation = (id % 3 == 0) ? 0.60 : 0.85;
  return hsvToRgb(hue, saturation, value);
}

Rgb8 displayColour(std::uint32_t id, const std::vector<int>& world_ids) {
  if (id != 0 && std::find(world_ids.begin(), world_ids.end(), int(id)) != world_ids.end()) return kWorldColour;
  return colourForId(id);
}

void segmentationPictureInto(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity,
                             double blend, const std::vector<int>& world_ids, std::uint8_t* rgb) {
  if (labels.count < 1 || int(ids.size()) != labels.count - 1)
    throw InputError("segmentation picture: " + std::to_string(ids.size()) + " segment ids for " +
                     std::to_string(labels.count) + " label planes (expected count - 1)");
  std::vector<Rgb8> colours;
  for (const int id : ids) colours.push_back(displayColour(std::uint32_t(std::max(id, 0)), world_ids));
  colours.push_back(colourForId(0));  // the outlier plane
  const bool have_image = intensity && intensity->sameSize(labels.width, labels.height);
  // A row at a time, plane after plane: each pixel's sums take their terms in plane order, as a loop over the
  // planes per pixel would (the same bits), but the row loop has no dependency from pixel to pixel and
  // vectorises. Planes with no positive weight add +0, which leaves the (non-negative) sums as they are. Rows in
  // parallel (the nodelet builds this picture for every pair).
  const int w = labels.width;
#pragma omp parallel
  {
    std::vector<double> sums(4 * std::size_t(w));
    double* const r = sums.data();
    double* const g = r + w;
    double* const b = g + w;
    double* const grey = b + w;
#pragma omp for schedule(static)
    for (int y = 0; y < labels.height; ++y) {
      std::fill(sums.begin(), sums.begin() + 3 * std::ptrdiff_t(w), 0.0);
      for (int i = 0; i < labels.count; ++i) {
        const float* u = labels.plane(i) + std::size_t(y) * std::size_t(w);
        const double cr = colours[std::size_t(i)].r, cg = colours[std::size_t(i)].g, cb = colours[std::size_t(i)].b;
        for (int x = 0; x < w; ++x) {
          // u if u > 0, else +0 (NaN too), as a bit mask: no branch, so the loop vectorises.
          std::uint32_t bits;
          std::memcpy(&bits, &u[x], sizeof bits);
          bits &= 0u - std::uint32_t(u[x] > 0.f);
          float positive;
          std::memcpy(&positive, &bits, sizeof positive);
          const double weight = positive;
          r[x] += weight * cr;
          g[x] += weight * cg;
          b[x] += weight * cb;
        }
      }
      if (have_image) {
        const float* row = &(*intensity)(0, y);
        for (int x = 0; x < w; ++x) grey[x] = 255.0 * std::clamp(double(row[x]), 0.0, 1.0);
      } else {
        std::fill(grey, grey + w, 128.0);
      }
      // lround(clamp(v, 0, 255)) without branches, so that the loop vectorises: in [0, 255] truncation is floor and
      // c - floor(c) is exact, so halves go up as lround sends them. NaN (only from a NaN intensity or blend) gives 0,
      // as lround's LONG_MIN cast to 8 bits did.
      std::uint8_t* out = rgb + std::size_t(y) * std::size_t(w) * 3;
      for (int x = 0; x < w; ++x) {
        const double mix[3] = {blend * r[x] + (1 - blend) * grey[x], blend * g[x] + (1 - blend) * grey[x],
                               blend * b[x] + (1 - blend) * grey[x]};
        for (int c = 0; c < 3; ++c) {
          double v = mix[c] >= 0.0 ? mix[c] : 0.0;  // NaN too
          v = v <= 255.0 ? v : 255.0;
          const int whole = int(v);
          out[3 * x + c] = std::uint8_t(whole + int(v - double(whole) >= 0.5));
        }
      }
    }
  }
}

ImageU8 segmentationPicture(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity,
                            double blend, const std::vector<int>& world_ids) {
  ImageU8 out(labels.width, labels.height, 3);
  segmentationPictureInto(labels, ids, intensity, blend, world_ids, out.data.data());
  return out;
}

}  // namespace mc_flow
