// Segment display colours (golden-ratio hue steps).
#include "mc_flow/core/palette.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

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

namespace {

// u if u > 0, else +0 (NaN too), as a bit mask: no branch, so the loops vectorise.
inline double positiveWeight(float u) {
  std::uint32_t bits;
  std::memcpy(&bits, &u, sizeof bits);
  bits &= 0u - std::uint32_t(u > 0.f);
  float positive;
  std::memcpy(&positive, &bits, sizeof positive);
  return positive;
}

// The blend of pixel sums with the grey, rounded as lround(clamp(v, 0, 255)) without branches: in [0, 255] truncation
// is floor and c - floor(c) is exact, so halves go up as lround sends them. NaN (only from a NaN intensity or blend)
// gives 0, as lround's LONG_MIN cast to 8 bits did.
inline void writePixels(const double* r, const double* g, const double* b, const float* grey_row, double blend, int n,
                        std::uint8_t* out) {
  for (int k = 0; k < n; ++k) {
    const double grey = grey_row ? 255.0 * std::clamp(double(grey_row[k]), 0.0, 1.0) : 128.0;
    const double mix[3] = {blend * r[k] + (1 - blend) * grey, blend * g[k] + (1 - blend) * grey,
                           blend * b[k] + (1 - blend) * grey};
    for (int c = 0; c < 3; ++c) {
      double v = mix[c] >= 0.0 ? mix[c] : 0.0;  // NaN too
      v = v <= 255.0 ? v : 255.0;
      const int whole = int(v);
      out[3 * k + c] = std::uint8_t(whole + int(v - double(whole) >= 0.5));
    }
  }
}

// Pixels [x0, x0 + n) of row y: each pixel's sums take their terms in plane order (planes with no positive weight add
// +0, which leaves the non-negative sums as they are).
void segmentationPixels(const SoftLabels& labels, const std::vector<Rgb8>& colours, const float* grey_row, double blend,
                        int y, int x0, int n, std::uint8_t* out) {
  constexpr int kMax = 8;
  const std::size_t at = std::size_t(y) * std::size_t(labels.width) + std::size_t(x0);
  for (int k0 = 0; k0 < n; k0 += kMax) {
    const int m = std::min(kMax, n - k0);
    double r[kMax] = {}, g[kMax] = {}, b[kMax] = {};
    for (int i = 0; i < labels.count; ++i) {
      const float* u = labels.plane(i) + at + std::size_t(k0);
      const Rgb8 c = colours[std::size_t(i)];
      for (int k = 0; k < m; ++k) {
        const double weight = positiveWeight(u[k]);
        r[k] += weight * double(c.r);
        g[k] += weight * double(c.g);
        b[k] += weight * double(c.b);
      }
    }
    writePixels(r, g, b, grey_row ? grey_row + x0 + k0 : nullptr, blend, m, out + 3 * std::size_t(k0));
  }
}

#if defined(__x86_64__) && defined(__GNUC__)
// segmentationPixels for 8 pixels at a time with AVX2: the sums stay in registers over the planes. The same double
// operations in the same order per pixel (a multiply, then an add: no FMA), so the same bits as the loop above.
// `colour_values`: each plane's colour as three doubles (r, g, b), the values the scalar loop converts per pixel.
__attribute__((target("avx2"))) void segmentationRowAvx2(const SoftLabels& labels, const std::vector<Rgb8>& colours,
                                                         const double* colour_values, const float* grey_row,
                                                         double blend, int y, std::uint8_t* out) {
  const int w = labels.width, chunks = w / 8;
  const std::size_t row = std::size_t(y) * std::size_t(w);
  for (int chunk = 0; chunk < chunks; ++chunk) {
    const int x0 = 8 * chunk;
    __m256d r0 = _mm256_setzero_pd(), r1 = r0, g0 = r0, g1 = r0, b0 = r0, b1 = r0;
    for (int i = 0; i < labels.count; ++i) {
      __m256 u = _mm256_loadu_ps(labels.plane(i) + row + std::size_t(x0));
      const __m256 positive = _mm256_cmp_ps(u, _mm256_setzero_ps(), _CMP_GT_OQ);
      // A plane with no share in these 8 pixels would add +0 to sums that are >= +0, which leaves them as they are:
      // skipped (most blocks hold one or two of the planes).
      if (_mm256_movemask_ps(positive) == 0) continue;
      u = _mm256_and_ps(u, positive);  // +0 unless u > 0
      const __m256d lo = _mm256_cvtps_pd(_mm256_castps256_ps128(u)), hi = _mm256_cvtps_pd(_mm256_extractf128_ps(u, 1));
      const double* c = colour_values + 3 * i;
      const __m256d cr = _mm256_broadcast_sd(c), cg = _mm256_broadcast_sd(c + 1), cb = _mm256_broadcast_sd(c + 2);
      r0 = _mm256_add_pd(r0, _mm256_mul_pd(lo, cr));
      r1 = _mm256_add_pd(r1, _mm256_mul_pd(hi, cr));
      g0 = _mm256_add_pd(g0, _mm256_mul_pd(lo, cg));
      g1 = _mm256_add_pd(g1, _mm256_mul_pd(hi, cg));
      b0 = _mm256_add_pd(b0, _mm256_mul_pd(lo, cb));
      b1 = _mm256_add_pd(b1, _mm256_mul_pd(hi, cb));
    }
    // writePixels' rule four lanes wide: the same operations (two products, then their sum), the clamps as blends
    // that keep a NaN where std::clamp keeps it, the mask that sends NaN and negatives to +0.
    const __m128 grey_floats = grey_row ? _mm_loadu_ps(grey_row + x0) : _mm_setzero_ps();
    const __m128 grey_floats_hi = grey_row ? _mm_loadu_ps(grey_row + x0 + 4) : _mm_setzero_ps();
    __m128i channel[3][2];  // per channel its 8 values, 4 per part
    const __m256d zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0), full = _mm256_set1_pd(255.0),
                  half = _mm256_set1_pd(0.5), weight = _mm256_set1_pd(blend), rest = _mm256_set1_pd(1 - blend);
    for (int part = 0; part < 2; ++part) {
      __m256d grey = _mm256_set1_pd(128.0);
      if (grey_row) {
        __m256d v = _mm256_cvtps_pd(part == 0 ? grey_floats : grey_floats_hi);
        v = _mm256_blendv_pd(v, zero, _mm256_cmp_pd(v, zero, _CMP_LT_OQ));
        v = _mm256_blendv_pd(v, one, _mm256_cmp_pd(one, v, _CMP_LT_OQ));
        grey = _mm256_mul_pd(full, v);
      }
      const __m256d grey_part = _mm256_mul_pd(rest, grey);
      const __m256d sums[3] = {part == 0 ? r0 : r1, part == 0 ? g0 : g1, part == 0 ? b0 : b1};
      for (int c = 0; c < 3; ++c) {
        __m256d v = _mm256_add_pd(_mm256_mul_pd(weight, sums[c]), grey_part);
        v = _mm256_and_pd(v, _mm256_cmp_pd(v, zero, _CMP_GE_OQ));
        v = _mm256_blendv_pd(full, v, _mm256_cmp_pd(v, full, _CMP_LE_OQ));
        const __m128i whole = _mm256_cvttpd_epi32(v);
        const __m256d up = _mm256_cmp_pd(_mm256_sub_pd(v, _mm256_cvtepi32_pd(whole)), half, _CMP_GE_OQ);
        // up is all ones (-1 as an integer) where the fraction is at least a half.
        const __m128i carry = _mm256_castsi256_si128(
            _mm256_permutevar8x32_epi32(_mm256_castpd_si256(up), _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7)));
        channel[c][part] = _mm_sub_epi32(whole, carry);
      }
    }
    // The values are in [0, 255]: packed to bytes (r0..r7 g0..g7 and b0..b7) and interleaved to r g b per pixel by
    // two byte shuffles (24 single-byte stores cost a third of the row's time).
    const __m128i rg = _mm_packus_epi16(_mm_packus_epi32(channel[0][0], channel[0][1]),
                                        _mm_packus_epi32(channel[1][0], channel[1][1]));
    const __m128i b = _mm_packus_epi16(_mm_packus_epi32(channel[2][0], channel[2][1]), _mm_setzero_si128());
    const __m128i first =
        _mm_or_si128(_mm_shuffle_epi8(rg, _mm_setr_epi8(0, 8, -1, 1, 9, -1, 2, 10, -1, 3, 11, -1, 4, 12, -1, 5)),
                     _mm_shuffle_epi8(b, _mm_setr_epi8(-1, -1, 0, -1, -1, 1, -1, -1, 2, -1, -1, 3, -1, -1, 4, -1)));
    const __m128i last =
        _mm_or_si128(_mm_shuffle_epi8(rg, _mm_setr_epi8(13, -1, 6, 14, -1, 7, 15, -1, -1, -1, -1, -1, -1, -1, -1, -1)),
                     _mm_shuffle_epi8(b, _mm_setr_epi8(-1, 5, -1, -1, 6, -1, -1, 7, -1, -1, -1, -1, -1, -1, -1, -1)));
    std::uint8_t* to = out + 3 * std::size_t(x0);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(to), first);
    _mm_storel_epi64(reinterpret_cast<__m128i*>(to + 16), last);
  }
  segmentationPixels(labels, colours, grey_row, blend, y, 8 * chunks, w - 8 * chunks,
                     out + 3 * std::size_t(8 * chunks));
}
#endif

void segmentationRow(const SoftLabels& labels, const std::vector<Rgb8>& colours, const double* colour_values,
                     const float* grey_row, double blend, int y, std::uint8_t* out) {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  if (avx2) return segmentationRowAvx2(labels, colours, colour_values, grey_row, blend, y, out);
#else
  (void)colour_values;
#endif
  segmentationPixels(labels, colours, grey_row, blend, y, 0, labels.width, out);
}

}  // namespace

SegmentationPainter::SegmentationPainter(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity,
                                         double blend, const std::vector<int>& world_ids)
    : labels_(labels),
      intensity_(intensity && intensity->sameSize(labels.width, labels.height) ? intensity : nullptr),
      blend_(blend) {
  if (labels.count < 1 || int(ids.size()) != labels.count - 1)
    throw InputError("segmentation picture: " + std::to_string(ids.size()) + " segment ids for " +
                     std::to_string(labels.count) + " label planes (expected count - 1)");
  for (const int id : ids) colours_.push_back(displayColour(std::uint32_t(std::max(id, 0)), world_ids));
  colours_.push_back(colourForId(0));  // the outlier plane
  for (const Rgb8& c : colours_) colour_values_.insert(colour_values_.end(), {double(c.r), double(c.g), double(c.b)});
}

void SegmentationPainter::paintRows(int first_row, int end_row, std::uint8_t* rgb) const {
  if (labels_.width <= 0) return;  // no pixels (and no row to point into)
  const std::size_t row_bytes = std::size_t(labels_.width) * 3;
  for (int y = std::max(first_row, 0); y < std::min(end_row, labels_.height); ++y)
    segmentationRow(labels_, colours_, colour_values_.data(), intensity_ ? &(*intensity_)(0, y) : nullptr, blend_, y,
                    rgb + std::size_t(y) * row_bytes);
}

void segmentationPictureInto(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity,
                             double blend, const std::vector<int>& world_ids, std::uint8_t* rgb) {
  const SegmentationPainter painter(labels, ids, intensity, blend, world_ids);
  // Rows in parallel (the nodelet builds this picture for every pair).
#pragma omp parallel for schedule(static)
  for (int y = 0; y < labels.height; ++y) painter.paintRows(y, y + 1, rgb);
}

ImageU8 segmentationPicture(const SoftLabels& labels, const std::vector<int>& ids, const ImageF* intensity,
                            double blend, const std::vector<int>& world_ids) {
  ImageU8 out(labels.width, labels.height, 3);
  segmentationPictureInto(labels, ids, intensity, blend, world_ids, out.data.data());
  return out;
}

}  // namespace mc_flow
