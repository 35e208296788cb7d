#include "mc_flow/core/image.h"

#include <cfloat>
#include <cmath>
#include <cstdio>

#include "mc_flow/core/error.h"

namespace mc_flow {

namespace {

std::string number(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.9g", v);
  return buf;
}

}  // namespace

void Intrinsics::validate() const {
  const char* names[4] = {"fx", "fy", "cx", "cy"};
  const double values[4] = {fx, fy, cx, cy};
  for (int i = 0; i < 4; ++i)
    if (!std::isfinite(values[i]))
      throw InputError(std::string("intrinsics: ") + names[i] + " = " + number(values[i]) + " is not finite");
  if (!(fx > 0)) throw InputError("intrinsics: fx = " + number(fx) + " must be > 0 [px]");
  if (!(fy > 0)) throw InputError("intrinsics: fy = " + number(fy) + " must be > 0 [px]");
}

std::string Intrinsics::toString() const {
  return "fx=" + number(fx) + " fy=" + number(fy) + " cx=" + number(cx) + " cy=" + number(cy) + " [px]";
}

void RgbdFrame::validate(const std::string& name) const {
  if (intensity.empty()) throw InputError(name + ": intensity image is empty (" + imageSizeText(intensity) + ")");
  if (depth.empty()) throw InputError(name + ": depth image is empty (" + imageSizeText(depth) + ")");
  if (intensity.channels != 1)
    throw InputError(name + ": intensity has " + std::to_string(intensity.channels) + " channels, expected 1");
  if (depth.channels != 1)
    throw InputError(name + ": depth has " + std::to_string(depth.channels) + " channels, expected 1");
  if (!depth.sameSize(intensity))
    throw InputError(name + ": depth is " + imageSizeText(depth) + " but intensity is " + imageSizeText(intensity));
  if (intensity.data.size() != intensity.pixelCount() || depth.data.size() != depth.pixelCount())
    throw InputError(name + ": image buffer size does not match its width x height");

  // A branch-free pass first (|v| <= FLT_MAX is false for NaN and infinity; GCC vectorises this loop, not one that
  // stops at the first bad value: 0.17 against 0.51 ms for a 1280x720 plane on the 2-core VM); only a frame that
  // fails it is searched for the pixel to name.
  int not_finite = 0;
  for (const float v : intensity.data) not_finite |= !(std::fabs(v) <= FLT_MAX);
  if (not_finite)
    for (int y = 0; y < intensity.height; ++y)
      for (int x = 0; x < intensity.width; ++x)
        if (!std::isfinite(intensity(x, y)))
          throw InputError(name + ": intensity at pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is " +
                           number(intensity(x, y)) + " (must be finite)");

  for (const float z : depth.data)
    if (isValidDepth(z)) return;
  throw InputError(name + ": no valid depth pixel (all 0, negative, infinite or NaN)");
}

}  // namespace mc_flow
