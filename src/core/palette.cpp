// Segment display colours (golden-ratio hue steps).
#include "mc_flow/core/palette.h"

#include <algorithm>
#include <cmath>

namespace mc_flow {

namespace {

Rgb8 hsvToRgb(double hue, double saturation, double value) {
  const double h = std::fmod(hue, 1.0) * 6.0;
  const int sector = int(h) % 6;
  const double f = h - std::floor(h);
  const double p = value * (1 - saturation), q = value * (1 - saturation * f), t = value * (1 - saturation * (1 - f));
  double r = 0, g = 0, b = 0;
  switch (sector) {
    case 0: r = value; g = t; b = p; break;
    case 1: r = q; g = value; b = p; break;
    case 2: r = p; g = value; b = t; break;
    case 3: r = p; g = q; b = value; break;
    case 4: r = t; g = p; b = value; break;
    default: r = value; g = p; b = q; break;
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

}  // namespace mc_flow
