#include "mc_flow/core/pyramid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "mc_flow/core/error.h"
#include "mc_flow/core/pyramid_pixel.h"

namespace mc_flow {

namespace {

// Every pyramid step halves with integer division: output pixel i covers input pixels 2i and 2i+1, so its
// centre sits at input coordinate 2i + 0.5, which is exactly what Intrinsics::scaled(0.5) assumes.
int halved(int n) { return std::max(1, n / 2); }

// Sorts four values with five compare-exchanges (`order(a, b)` leaves the smaller in a): the same steps whatever the
// values, in the scalar function and in each lane of the SSE one.
template <typename T, typename Order>
void sortFour(T c[4], Order order) {
  order(c[0], c[1]);
  order(c[2], c[3]);
  order(c[0], c[2]);
  order(c[1], c[3]);
  order(c[1], c[2]);
}

// pyramid_pixel::downsampledDepth for an output pixel whose whole 4x4 window lies inside the image (rows
// r0..r3 = input rows 2y-1..2y+2, window columns x0..x0+3 with x0 = 2x-1): the same float operations in the
// same order, so the same bits, without the border tests and without branches on the data where the shared
// function has them (absF, the insertion sort). With sensor noise the signs of z - reference and the order of
// the central values are random, and those branches were mispredicted about half the time: on the real pairs'
// depth (shared/data/real_pairs, 640x480, one core of the 2-core VM) the shared function took 2.8-3.4 ms, this
// one 1.1-1.3 ms, the SSE one below 0.6 ms (docs/PERFORMANCE.md, "Nodelet overhead per pair"). The tail of a
// row after the SSE blocks, and builds without SSE2, use this one.
inline float interiorDownsampledDepth(const float* r0, const float* r1, const float* r2, const float* r3, int x0,
                                      float max_diff) {
  // The valid central values ascending, the invalid ones as +inf after them: a sorting network of min/max.
  const float inf = std::numeric_limits<float>::infinity();
  float c[4] = {r1[x0 + 1], r1[x0 + 2], r2[x0 + 1], r2[x0 + 2]};
  int n = 0;
  for (float& v : c) {
    const bool valid = pyramid_pixel::validDepth(v);
    n += valid ? 1 : 0;
    v = valid ? v : inf;
  }
  if (n == 0) return 0.f;
  const auto order = [](float& a, float& b) {
    const float lo = std::min(a, b), hi = std::max(a, b);
    a = lo;
    b = hi;
  };
  sortFour(c, order);
  const float reference = c[(n - 1) / 2];
  const float k[4] = {1.f, 3.f, 3.f, 1.f};
  const float* rows[4] = {r0, r1, r2, r3};
  float sum_w = 0.f, sum_z = 0.f;
  for (int t = 0; t < 4; ++t) {
    const float* row = rows[t] + x0;
    for (int s = 0; s < 4; ++s) {
      const float z = row[s];
      // |z - reference| compares the same with fabs as with absF (they differ only in the sign of -0).
      const bool ok = pyramid_pixel::validDepth(z) & !(std::fabs(z - reference) > max_diff);
      const float weight = ok ? k[t] * k[s] : 0.f;  // adding +0 leaves both sums as they are
      sum_w = sum_w + weight;
      sum_z = sum_z + weight * (ok ? z : 0.f);
    }
  }
  return sum_z / sum_w;
}

#if defined(__SSE2__)
// interiorDownsampledDepth for four neighbouring output pixels at once, one per SSE lane (x86-64 always has SSE2):
// each lane does the same float operations in the same order as the scalar function, so the same bits. Lane p
// reads window columns x0 + 2p .. x0 + 2p + 3 (x0 = 2x - 1 for the first pixel x): the caller keeps the last
// lane's window inside the row.
inline void interiorDownsampledDepth4(const float* const rows[4], int x0, float max_diff, float* out) {
  const __m128 zero = _mm_setzero_ps(), largest = _mm_set1_ps(std::numeric_limits<float>::max());
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 limit = _mm_set1_ps(max_diff);
  // Sample s (0..3) of each lane's window in a row: even or odd columns of eight consecutive floats.
  const auto samples = [&](const float* row, int s) {
    const float* from = row + x0 + (s & 2);
    const __m128 a = _mm_loadu_ps(from), b = _mm_loadu_ps(from + 4);
    return (s & 1) ? _mm_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1)) : _mm_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0));
  };
  const auto valid = [&](__m128 z) { return _mm_and_ps(_mm_cmpgt_ps(z, zero), _mm_cmple_ps(z, largest)); };
  __m128 c[4] = {samples(rows[1], 1), samples(rows[1], 2), samples(rows[2], 1), samples(rows[2], 2)};
  __m128i n = _mm_setzero_si128();
  for (__m128& v : c) {
    const __m128 ok = valid(v);
    n = _mm_sub_epi32(n, _mm_castps_si128(ok));  // + 1 in each lane where v is valid
    v = _mm_or_ps(_mm_and_ps(ok, v), _mm_andnot_ps(ok, inf));
  }
  const auto order = [](__m128& a, __m128& b) {
    const __m128 lo = _mm_min_ps(a, b), hi = _mm_max_ps(a, b);
    a = lo;
    b = hi;
  };
  sortFour(c, order);
  // The lower median c[(n - 1) / 2]: c[1] for n = 3, 4, else c[0].
  const __m128 upper = _mm_castsi128_ps(_mm_cmpgt_epi32(n, _mm_set1_epi32(2)));
  const __m128 reference = _mm_or_ps(_mm_and_ps(upper, c[1]), _mm_andnot_ps(upper, c[0]));
  const float k[4] = {1.f, 3.f, 3.f, 1.f};
  __m128 sum_w = zero, sum_z = zero;
  for (int t = 0; t < 4; ++t)
    for (int s = 0; s < 4; ++s) {
      const __m128 z = samples(rows[t], s);
      const __m128 difference = _mm_and_ps(_mm_sub_ps(z, reference), magnitude);
      const __m128 ok = _mm_and_ps(valid(z), _mm_cmpngt_ps(difference, limit));
      const __m128 weight = _mm_and_ps(ok, _mm_set1_ps(k[t] * k[s]));
      sum_w = _mm_add_ps(sum_w, weight);
      sum_z = _mm_add_ps(sum_z, _mm_mul_ps(weight, _mm_and_ps(ok, z)));
    }
  const __m128 none = _mm_castsi128_ps(_mm_cmpeq_epi32(n, _mm_setzero_si128()));
  _mm_storeu_ps(out, _mm_andnot_ps(none, _mm_div_ps(sum_z, sum_w)));
}
#endif

#if defined(__x86_64__) && defined(__GNUC__)
// interiorDownsampledDepth4 eight lanes wide, for CPUs with AVX2 (chosen at run time): each lane does the scalar
// function's float operations in its order, so the same bits. Lane p reads window columns x0 + 2p .. x0 + 2p + 3; the
// caller keeps the last lane's window (and the 16 floats each load reads) inside the row.
__attribute__((target("avx2"))) inline __m256 depthSamples8(const float* row, int x0, int s) {
  const float* from = row + x0 + (s & 2);
  const __m256 a = _mm256_loadu_ps(from), b = _mm256_loadu_ps(from + 8);
  // Within each 128-bit half the even (odd) columns of a and b, then the halves in column order.
  const __m256 picked =
      (s & 1) ? _mm256_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1)) : _mm256_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0));
  return _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(picked), _MM_SHUFFLE(3, 1, 2, 0)));
}

__attribute__((target("avx2"))) inline __m256 validDepth8(__m256 z) {
  return _mm256_and_ps(_mm256_cmp_ps(z, _mm256_setzero_ps(), _CMP_GT_OQ),
                       _mm256_cmp_ps(z, _mm256_set1_ps(std::numeric_limits<float>::max()), _CMP_LE_OQ));
}

__attribute__((target("avx2"))) inline void order8(__m256& a, __m256& b) {
  const __m256 lo = _mm256_min_ps(a, b), hi = _mm256_max_ps(a, b);
  a = lo;
  b = hi;
}

__attribute__((target("avx2"))) void interiorDownsampledDepth8(const float* const rows[4], int x0, float max_diff,
                                                               float* out) {
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  const __m256 magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 limit = _mm256_set1_ps(max_diff);
  __m256 c[4] = {depthSamples8(rows[1], x0, 1), depthSamples8(rows[1], x0, 2), depthSamples8(rows[2], x0, 1),
                 depthSamples8(rows[2], x0, 2)};
  __m256i n = _mm256_setzero_si256();
  for (__m256& v : c) {
    const __m256 ok = validDepth8(v);
    n = _mm256_sub_epi32(n, _mm256_castps_si256(ok));  // + 1 in each lane where v is valid
    v = _mm256_blendv_ps(inf, v, ok);
  }
  // sortFour's network.
  order8(c[0], c[1]);
  order8(c[2], c[3]);
  order8(c[0], c[2]);
  order8(c[1], c[3]);
  order8(c[1], c[2]);
  // The lower median c[(n - 1) / 2]: c[1] for n = 3, 4, else c[0].
  const __m256 upper = _mm256_castsi256_ps(_mm256_cmpgt_epi32(n, _mm256_set1_epi32(2)));
  const __m256 reference = _mm256_blendv_ps(c[0], c[1], upper);
  const float k[4] = {1.f, 3.f, 3.f, 1.f};
  __m256 sum_w = _mm256_setzero_ps(), sum_z = _mm256_setzero_ps();
  for (int t = 0; t < 4; ++t)
    for (int s = 0; s < 4; ++s) {
      const __m256 z = depthSamples8(rows[t], x0, s);
      const __m256 difference = _mm256_and_ps(_mm256_sub_ps(z, reference), magnitude);
      const __m256 ok = _mm256_and_ps(validDepth8(z), _mm256_cmp_ps(difference, limit, _CMP_NGT_UQ));
      const __m256 weight = _mm256_and_ps(ok, _mm256_set1_ps(k[t] * k[s]));
      sum_w = _mm256_add_ps(sum_w, weight);
      sum_z = _mm256_add_ps(sum_z, _mm256_mul_ps(weight, _mm256_and_ps(ok, z)));
    }
  const __m256 none = _mm256_castsi256_ps(_mm256_cmpeq_epi32(n, _mm256_setzero_si256()));
  _mm256_storeu_ps(out, _mm256_andnot_ps(none, _mm256_div_ps(sum_z, sum_w)));
}

// The row's interior output pixels from x on, eight at a time; returns the first pixel not done.
__attribute__((target("avx2"))) int interiorDepthRowAvx2(const float* const rows[4], int x, int ow, int w,
                                                         float max_diff, float* o) {
  for (; x + 7 < ow && 2 * (x + 7) + 2 < w; x += 8) interiorDownsampledDepth8(rows, 2 * x - 1, max_diff, o + x);
  return x;
}

bool haveAvx2() {
  static const bool avx2 = __builtin_cpu_supports("avx2");
  return avx2;
}
#endif

}  // namespace

int PyramidLevel::validCount() const {
  int n = 0;
  for (const float z : depth.data) n += z > 0.f ? 1 : 0;
  return n;
}

int pyramidLevelCount(int width, int height, int coarsest_min_width) {
  const int min_width = std::max(1, coarsest_min_width);
  int levels = 1;
  while (width / 2 >= min_width && height / 2 >= 1) {
    width /= 2;
    height /= 2;
    ++levels;
  }
  return levels;
}

int pyramidLevelExtent(int n, int level) {
  for (int l = 0; l < level; ++l) n = halved(n);
  return n;
}

ImageF downsampleIntensity(const ImageF& image) {
  if (image.empty()) throw InputError("downsampleIntensity: empty image");
  const int w = image.width, h = image.height, ow = halved(w), oh = halved(h), c = image.channels;
  ImageF horizontal(ow, h, c);
  ImageF out(ow, oh, c);
  if (c == 1) {
    // The same two passes (pyramid_pixel::filter1331 on the same samples), with the samples of interior pixels
    // read straight from their rows instead of through clamped indices: the same bits, and loops that vectorise.
#pragma omp parallel
    {
#pragma omp for schedule(static)
      for (int y = 0; y < h; ++y) {
        const float* in = &image(0, y);
        float* row = &horizontal(0, y);
        const auto at = [&](int xi, int yi) { return image(xi, yi); };
        int x = 0;
        if (ow > 1) row[x++] = pyramid_pixel::downsampleRow(at, w, 0, y);
        for (; x < ow && 2 * x + 2 < w; ++x)
          row[x] = pyramid_pixel::filter1331(in[2 * x - 1], in[2 * x], in[2 * x + 1], in[2 * x + 2]);
        for (; x < ow; ++x) row[x] = pyramid_pixel::downsampleRow(at, w, x, y);
      }
#pragma omp for schedule(static)
      for (int y = 0; y < oh; ++y) {
        const float* r0 = &horizontal(0, pyramid_pixel::clampIndex(2 * y - 1, h));
        const float* r1 = &horizontal(0, pyramid_pixel::clampIndex(2 * y, h));
        const float* r2 = &horizontal(0, pyramid_pixel::clampIndex(2 * y + 1, h));
        const float* r3 = &horizontal(0, pyramid_pixel::clampIndex(2 * y + 2, h));
        float* row = &out(0, y);
        for (int x = 0; x < ow; ++x) row[x] = pyramid_pixel::filter1331(r0[x], r1[x], r2[x], r3[x]);
      }
    }
    return out;
  }
  // The two passes of pyramid_pixel::downsampledIntensity, each pixel once.
#pragma omp parallel
  {
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y)
      for (int ch = 0; ch < c; ++ch) {
        const auto at = [&](int xi, int yi) { return image(xi, yi, ch); };
        for (int x = 0; x < ow; ++x) horizontal(x, y, ch) = pyramid_pixel::downsampleRow(at, w, x, y);
      }
#pragma omp for schedule(static)
    for (int y = 0; y < oh; ++y)
      for (int x = 0; x < ow; ++x)
        for (int ch = 0; ch < c; ++ch) {
          const auto at = [&](int xi, int yi) { return horizontal(xi, yi, ch); };
          out(x, y, ch) = pyramid_pixel::filter1331(
              at(x, pyramid_pixel::clampIndex(2 * y - 1, h)), at(x, pyramid_pixel::clampIndex(2 * y, h)),
              at(x, pyramid_pixel::clampIndex(2 * y + 1, h)), at(x, pyramid_pixel::clampIndex(2 * y + 2, h)));
        }
  }
  return out;
}

ImageF downsampleDepth(const ImageF& depth, double range) {
  if (depth.empty()) throw InputError("downsampleDepth: empty image");
  if (depth.channels != 1)
    throw InputError("downsampleDepth: " + std::to_string(depth.channels) + " channels, expected 1");
  const int w = depth.width, h = depth.height, ow = halved(w), oh = halved(h);
  const float max_diff = float(range);
  const auto at = [&](int x, int y) { return depth(x, y); };
  ImageF out(ow, oh, 1, 0.f);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < oh; ++y) {
    float* o = &out(0, y);
    int x = 0;
    if (y >= 1 && 2 * y + 2 < h) {  // the window's rows are inside: the interior columns take the fast path
      const float* r0 = &depth(0, 2 * y - 1);
      const float *r1 = r0 + w, *r2 = r1 + w, *r3 = r2 + w;
      o[0] = pyramid_pixel::downsampledDepth(at, w, h, 0, y, max_diff);
      x = 1;
#if defined(__SSE2__)
      const float* const rows[4] = {r0, r1, r2, r3};
#if defined(__x86_64__) && defined(__GNUC__)
      if (haveAvx2()) x = interiorDepthRowAvx2(rows, x, ow, w, max_diff, o);
#endif
      for (; x + 3 < ow && 2 * (x + 3) + 2 < w; x += 4) interiorDownsampledDepth4(rows, 2 * x - 1, max_diff, o + x);
#endif
      for (; 2 * x + 2 < w && x < ow; ++x) o[x] = interiorDownsampledDepth(r0, r1, r2, r3, 2 * x - 1, max_diff);
    }
    for (; x < ow; ++x) o[x] = pyramid_pixel::downsampledDepth(at, w, h, x, y, max_diff);
  }
  return out;
}

ImageF backProject(const ImageF& depth, const Intrinsics& K) {
  if (depth.channels != 1) throw InputError("backProject: depth has " + std::to_string(depth.channels) + " channels");
  const int w = depth.width, h = depth.height;
  ImageF points(w, h, 3);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double inv_fx = 1.0 / K.fx, inv_fy = 1.0 / K.fy;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float z = depth(x, y);
      float* p = &points(x, y, 0);
      if (isValidDepth(z))
        pyramid_pixel::backProjectPixel(z, x, y, K.cx, K.cy, inv_fx, inv_fy, p);
      else
        p[0] = p[1] = p[2] = nan;
    }
  return points;
}

ImageF blendedGradient(const ImageF& f, const ImageF* validity_source, float eps) {
  if (f.channels != 1)
    throw InputError("blendedGradient: image has " + std::to_string(f.channels) + " channels, expected 1");
  if (validity_source && !validity_source->sameSize(f))
    throw InputError("blendedGradient: validity source size differs from the image");
  const int w = f.width, h = f.height;
  ImageF grad(w, h, 2, 0.f);
  const auto at = [&](int x, int y) { return f(x, y); };
  const auto usable = [&](int x, int y) { return !validity_source || isValidDepth((*validity_source)(x, y)); };
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) pyramid_pixel::blendedGradientAt(at, usable, w, h, x, y, eps, &grad(x, y, 0));
  return grad;
}

Pyramid buildPyramid(const RgbdFrame& frame, const Intrinsics& K, int levels, const Config& config) {
  if (levels < 1) throw InputError("buildPyramid: levels = " + std::to_string(levels) + " must be >= 1");
  if (frame.intensity.empty() || !frame.depth.sameSize(frame.intensity))
    throw InputError("buildPyramid: intensity " + std::to_string(frame.intensity.width) + "x" +
                     std::to_string(frame.intensity.height) + " and depth " + std::to_string(frame.depth.width) + "x" +
                     std::to_string(frame.depth.height) + " must be non-empty and of the same size");

  Pyramid pyramid;
  pyramid.levels.resize(std::size_t(levels));

  PyramidLevel& base = pyramid.levels[0];
  base.intensity = frame.intensity;
  base.depth = frame.depth;
  const float min_depth = float(config.min_depth), max_depth = float(config.max_depth);
  float* z = base.depth.ptr();
  const long n = long(base.depth.data.size());
#pragma omp parallel for schedule(static)
  for (long i = 0; i < n; ++i) z[i] = pyramid_pixel::cleanDepth(z[i], min_depth, max_depth);

  for (int l = 0; l < levels; ++l) {
    PyramidLevel& level = pyramid.levels[std::size_t(l)];
    if (l > 0) {
      const PyramidLevel& finer = pyramid.levels[std::size_t(l - 1)];
      level.intensity = downsampleIntensity(finer.intensity);
      level.depth = downsampleDepth(finer.depth, config.depth_downsample_range);
    }
    level.intrinsics = K.scaled(std::ldexp(1.0, -l));
    level.points = backProject(level.depth, level.intrinsics);
    level.intensity_grad = blendedGradient(level.intensity, nullptr, pyramid_pixel::kIntensityGradientEps);
    level.depth_grad = blendedGradient(level.depth, &level.depth, pyramid_pixel::kDepthGradientEps);
  }
  return pyramid;
}

}  // namespace mc_flow
