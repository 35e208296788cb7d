// The CPU backend of the solve's stages: the stage functions of src/core on host images (the reference
// for cuda/solve_backend.cu), and the backend selection.
#include "mc_flow/core/solve_backend.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "mc_flow/core/error.h"
#include "mc_flow/core/kmeans.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/occlusion.h"
#include "mc_flow/core/scene_flow.h"

#ifdef _OPENMP
#include <omp.h>
#endif

namespace mc_flow {

namespace {

// The size and the value range of hard labels: [-1, labels).
void validateHardLabelValues(const ImageI32& hard, int labels, int width, int height) {
  if (hard.width != width || hard.height != height || hard.channels != 1)
    throw InputError("initial labels: a " + std::to_string(hard.width) + "x" + std::to_string(hard.height) + "x" +
                     std::to_string(hard.channels) + " image for a " + std::to_string(width) + "x" +
                     std::to_string(height) + " level");
  for (std::size_t k = 0; k < hard.data.size(); ++k)
    if (hard.data[k] < -1 || hard.data[k] >= labels)
      throw InputError("initial labels: pixel " + std::to_string(k) + " has label " + std::to_string(hard.data[k]) +
                       ", outside [-1, " + std::to_string(labels) + ")");
}

}  // namespace

void requireMotionLabels(int motion_labels) {
  if (motion_labels < 1)
    throw InputError("initial labels: " + std::to_string(motion_labels) + " motion labels, need at least 1");
}

void validateHardLabels(const ImageI32& hard, int motion_labels, int width, int height) {
  requireMotionLabels(motion_labels);
  validateHardLabelValues(hard, motion_labels, width, height);
}

void validateCarriedHardLabels(const ImageI32& hard, int first_new, int width, int height) {
  if (first_new < 0) throw InputError("initial labels: the new clusters numbered from " + std::to_string(first_new));
  validateHardLabelValues(hard, first_new, width, height);
}

std::vector<Eigen::Vector3f> SolveBackend::kmeansCentres(int level, int k, int max_iterations, double tolerance_m,
                                                         unsigned seed) {
  return kmeansPoints(framePoints(level), k, max_iterations, tolerance_m, seed).centres;
}

CarriedSegments SolveBackend::carrySegments(const Result& previous, const ImageF& frame1_depth, int label_level,
                                            const Config& config) {
  if (label_level < 0) return mc_flow::carrySegments(previous, frame1_depth, nullptr, 1, config);
  const ImageF& level_points = framePoints(label_level);  // throws InputError for a level the pyramid lacks
  return mc_flow::carrySegments(previous, frame1_depth, &level_points, 1 << label_level, config);
}

void SolveBackend::initialiseLabelsFromCentres(int level, const std::vector<Eigen::Vector3f>& centres) {
  if (centres.empty()) throw InputError("initial labels from K-means: no centre given");
  initialiseLabels(level, assignToNearestCentre(framePoints(level), centres), int(centres.size()));
}

int SolveBackend::initialiseLabelsWithUncoveredClusters(int level, const ImageI32& carried, int first_new, int clusters,
                                                        const Config& config) {
  const ImageF& points = framePoints(level);
  validateCarriedHardLabels(carried, first_new, points.width, points.height);
  ImageI32 hard = carried;  // the carried labels, then the clusters
  // The uncovered pixels' points in pixel order, as kmeansPoints takes an image's valid points (a list of the few
  // instead of an image of the level: no pages to fill per pair).
  std::vector<Eigen::Vector3f> open_points;
  std::vector<std::size_t> open_pixels;
  for (std::size_t k = 0; k < hard.data.size(); ++k) {
    const float* P = points.data.data() + 3 * k;
    if (hard.data[k] < 0 && std::isfinite(P[0]) && std::isfinite(P[1]) && std::isfinite(P[2])) {
      open_points.emplace_back(P[0], P[1], P[2]);
      open_pixels.push_back(k);
    }
  }
  const KMeansPointsResult kmeans =
      kmeansPointList(open_points, clusters, config.kmeans_max_iterations, config.kmeans_tolerance, config.seed);
  for (std::size_t i = 0; i < kmeans.assignment.size(); ++i)
    hard.data[open_pixels[i]] = first_new + kmeans.assignment[i];
  const int kept = int(kmeans.centres.size());
  initialiseLabels(level, hard, first_new + kept);
  return kept;
}

namespace {

// Nearest-pixel resampling of a mask (or of carried labels) to another pyramid level (pixel-centre aligned). Levels
// differ by a power of two (integer halving drops an odd last column/row), so the scale is 2^k, not the size ratio.
template <typename T>
Image<T> resampleMask(const Image<T>& mask, int width, int height) {
  if (mask.sameSize(width, height)) return mask;
  Image<T> out(width, height, 1, 0);
  const double scale = std::exp2(std::round(std::log2(double(mask.width) / double(width))));  // source px per target px
  for (int y = 0; y < height; ++y) {
    const int sy = std::clamp(int(std::floor((y + 0.5) * scale)), 0, mask.height - 1);
    for (int x = 0; x < width; ++x) {
      const int sx = std::clamp(int(std::floor((x + 0.5) * scale)), 0, mask.width - 1);
      out(x, y) = mask(sx, sy);
    }
  }
  return out;
}

// Labels of one pyramid level carried to another.
SoftLabels labelsAtLevel(const SoftLabels& u, int from_level, int to_level, const Pyramid& pyramid) {
  if (to_level == from_level) return u;
  if (to_level < from_level) return upsampleLabels(u, pyramid[to_level].points.width, pyramid[to_level].points.height);
  SoftLabels out = u;
  for (int level = from_level + 1; level <= to_level; ++level)
    out = downsampleLabels(out, pyramid[level].points.width, pyramid[level].points.height);
  return out;
}

class CpuSolveBackend final : public SolveBackend {
 public:
  CpuSolveBackend() : accumulator_(makeCpuMotionAccumulator()), optimizer_(makeCpuLabelOptimizer()) {}

  Backend kind() const override { return Backend::Cpu; }

  void buildPyramids(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, int levels,
                     const Config& config) override {
    K_ = K;
    pyramid1_ = buildPyramid(frame1, K, levels, config);
    pyramid2_ = buildPyramid(frame2, K, levels, config);
    valid_counts_.clear();
    for (int l = 0; l < levels; ++l) valid_counts_.push_back(pyramid1_[l].validCount());
    u_ = SoftLabels();
    carried_ = ImageI32();
    level_ = 0;
    occlusion_ = ImageU8();
    dual_ = LabelDual();
    weights_level_ = -1;
  }

  void initialiseLabels(int level, const ImageI32& hard, int motion_labels) override {
    const PyramidLevel& L = pyramid1_[level];
    validateHardLabels(hard, motion_labels, L.points.width, L.points.height);
    u_ = SoftLabels(L.points.width, L.points.height, motion_labels + 1, 0.f);
    for (std::size_t k = 0; k < hard.data.size(); ++k) {
      const int a = std::isfinite(L.points.data[k * 3 + 2]) ? hard.data[k] : -1;
      u_.plane(a >= 0 ? a : u_.outlier())[k] = 1.f;
    }
    carried_ = ImageI32();
    level_ = level;
    occlusion_ = ImageU8(L.points.width, L.points.height, 1, 0);
    dual_ = LabelDual();
  }

  const ImageF& framePoints(int level) override { return levelOf(pyramid1_, level).points; }
  const std::vector<int>& validCounts() const override { return valid_counts_; }

  void holdCarriedLabels(int carried_labels) override {
    carried_ = ImageI32();
    if (carried_labels <= 0) return;
    const ImageI32 initial = u_.argmax();
    carried_ = ImageI32(u_.width, u_.height, 1, -1);
    for (std::size_t k = 0; k < initial.data.size(); ++k)
      if (initial.data[k] < std::min(carried_labels, u_.count - 1)) carried_.data[k] = initial.data[k];
  }

  void moveLabels(int level) override {
    const PyramidLevel& to = levelOf(pyramid1_, level);  // checks the level
    if (!carried_.data.empty()) carried_ = resampleMask(carried_, to.points.width, to.points.height);
    u_ = labelsAtLevel(u_, level_, level, pyramid1_);
    level_ = level;
    occlusion_ = ImageU8(u_.width, u_.height, 1, 0);
    dual_ = LabelDual();
  }

  MotionAccumulator& motionAccumulator(int level, MotionLabels which, bool use_occlusion,
                                       const Config& config) override {
    const PyramidLevel& P = pyramid1_[level];
    if (which == MotionLabels::AllValidAsOne) {
      level_labels_ = SoftLabels(P.points.width, P.points.height, 2, 0.f);
      for (std::size_t k = 0; k < level_labels_.planeSize(); ++k)
        level_labels_.plane(std::isfinite(P.points.data[k * 3 + 2]) ? 0 : 1)[k] = 1.f;
    } else {
      level_labels_ = labelsAtLevel(u_, level_, level, pyramid1_);
    }
    if (use_occlusion) level_occlusion_ = resampleMask(occlusion_, P.points.width, P.points.height);
    accumulator_->setLevel(P, pyramid2_[level], level_labels_, use_occlusion ? &level_occlusion_ : nullptr, config);
    return *accumulator_;
  }

  void updateOcclusion(const std::vector<Vector6d>& twists, const Config& config) override {
    const PyramidLevel& L = pyramid1_[level_];
    occlusion_ = detectOcclusions(warpPoints(L.points, u_, twists), pyramid2_[level_].depth, L.intrinsics, config);
  }

  LabelStepStats labelStep(const std::vector<Vector6d>& twists, bool use_occlusion, int iterations, double tolerance,
                           const Config& config) override {
    const PyramidLevel& L = pyramid1_[level_];
    if (weights_level_ != level_) {
      geometricWeights(L, config.min_geometric_weight, problem_.weight_x, problem_.weight_y);
      weights_level_ = level_;
    }
    computeDataCosts(L, pyramid2_[level_], twists, use_occlusion ? &occlusion_ : nullptr, config, problem_);
    if (!carried_.data.empty()) addSwitchingCost(carried_, float(config.warm_switch_cost), problem_);
    const SoftLabels before = u_;
    const LabelStats ls = optimizer_->optimize(problem_, u_, dual_, iterations, tolerance);
    LabelStepStats out;
    out.iterations = ls.iterations;
    out.energy = ls.energy;  // E(u) of eq. 4, without the switching cost
    if (!carried_.data.empty()) out.energy -= switchingEnergy(carried_, float(config.warm_switch_cost), problem_, u_);
    double change = 0;
    for (std::size_t i = 0; i < u_.data.size(); ++i) change += std::fabs(u_.data[i] - before.data[i]);
    out.mean_change = change / double(u_.planeSize());
    return out;
  }

  SoftLabels downloadLabels() override { return u_; }

  void outputs(const std::vector<Vector6d>& twists, const Config& config, const OutputSelection& selection,
               Result& result) override {
    if (int(twists.size()) != u_.count - 1)
      throw InputError("CPU backend outputs: " + std::to_string(twists.size()) + " twists for " +
                       std::to_string(u_.count - 1) + " motion labels");
    const PyramidLevel& F0 = pyramid1_[0];
    const int W = F0.points.width, H = F0.points.height;
    result.soft_labels = level_ == 0 ? u_ : labelsAtLevel(u_, level_, 0, pyramid1_);
    // Pixels without depth belong to the outlier label whatever the upsampling blended in.
    const int outlier = result.soft_labels.outlier();
    for (std::size_t k = 0; k < result.soft_labels.planeSize(); ++k)
      if (!std::isfinite(F0.points.data[k * 3 + 2]))
        for (int i = 0; i < result.soft_labels.count; ++i) result.soft_labels.plane(i)[k] = i == outlier ? 1.f : 0.f;
    const ImageF warped = warpPoints(F0.points, result.soft_labels, twists);
    sceneAndOpticalFlow(F0.points, warped, K_, result.scene_flow, result.optical_flow);
    result.moved_depth = ImageF(W, H, 1);
    for (std::size_t k = 0; k < result.moved_depth.data.size(); ++k)
      result.moved_depth.data[k] = warped.data[k * 3 + 2];
    result.occlusion =
        config.detect_occlusions ? detectOcclusions(warped, pyramid2_[0].depth, K_, config) : ImageU8(W, H, 1, 0);
    const ImageI32 argmax = result.soft_labels.argmax();
    result.labels = ImageI32(W, H, 1, 0);
    for (std::size_t k = 0; k < argmax.data.size(); ++k) {
      const int a = argmax.data[k];
      result.labels.data[k] = (a == outlier || !std::isfinite(F0.points.data[k * 3 + 2])) ? 0 : a + 1;
    }
    const std::vector<Eigen::Vector3d> centroids = labelCentroids(result.soft_labels, F0.points);
    result.segments.assign(twists.size(), Segment());
    for (std::size_t i = 0; i < twists.size(); ++i) {
      result.segments[i].support = result.soft_labels.support(int(i));
      result.segments[i].centroid = centroids[i];
    }
    // Computed on the way (argmax, centroids, the warp), kept only when selected.
    if (!selection.soft_labels) {
      result.soft_labels.width = result.soft_labels.height = result.soft_labels.count = 0;
      result.soft_labels.data.clear();
    }
    if (!selection.scene_flow) {
      result.scene_flow.width = result.scene_flow.height = 0;
      result.scene_flow.data.clear();
    }
  }

  // ---- LabelStore: the host store over the current labels
  int labelCount() const override { return u_.count; }
  std::vector<double> supports() override { return store().supports(); }
  void remap(const std::vector<int>& target, int new_count) override {
    const int old_count = u_.count;
    store().remap(target, new_count);
    for (std::int32_t& c : carried_.data)  // a merged label's pixels start in the merged label; removed: none
      if (c >= 0) c = target[std::size_t(c)] == new_count - 1 ? -1 : target[std::size_t(c)];
    if (new_count != old_count) dual_ = LabelDual();
  }
  std::vector<LabelMoments> ownedMoments() override { return store().ownedMoments(); }
  CutTrial trialCuts(const std::vector<LabelCut>& cuts, const std::vector<Vector6d>& twists, bool use_occlusion,
                     const Config& config) override {
    return store().trialCuts(cuts, twists, use_occlusion, config);
  }
  void applyCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) override {
    if (!cuts.empty()) dual_ = LabelDual();
    const int first_new = u_.count - 1;
    store().applyCuts(cuts, use_occlusion, config);
    // A cut's pixels are free of the switching cost: the label step decides between the halves on the data alone.
    if (!carried_.data.empty())
      for (std::size_t k = 0; k < carried_.data.size(); ++k)
        for (int c = 0; c < int(cuts.size()); ++c)
          if (u_.plane(first_new + c)[k] > 0.f) carried_.data[k] = -1;
  }
  LabelCostModel costModel(const std::vector<Vector6d>& twists, bool use_occlusion, const Config& config) override {
    return store().costModel(twists, use_occlusion, config);
  }

 private:
  HostLabelStore store() {
    return HostLabelStore(u_, pyramid1_[level_], pyramid2_[level_], &occlusion_, accumulator_.get());
  }

  ImageI32 carried_;  // holdCarriedLabels: the carried label each pixel started in (-1: none), at level_
  std::unique_ptr<MotionAccumulator> accumulator_;
  std::unique_ptr<LabelOptimizer> optimizer_;
  static const PyramidLevel& levelOf(const Pyramid& pyramid, int level) {
    if (level < 0 || level >= pyramid.size())
      throw InputError("CPU backend: pyramid level " + std::to_string(level) + " outside [0, " +
                       std::to_string(pyramid.size()) + ")");
    return pyramid[level];
  }

  Intrinsics K_;  // the input's, as given (level 0's are K.scaled(1), which may differ in the last bit)
  Pyramid pyramid1_, pyramid2_;
  std::vector<int> valid_counts_;
  SoftLabels u_, level_labels_;
  int level_ = 0;
  ImageU8 occlusion_, level_occlusion_;
  LabelProblem problem_;
  LabelDual dual_;
  int weights_level_ = -1;
};

}  // namespace

int fillOutputImages(const StagedOutputs& s, Result& result) {
  const int W = s.width, H = s.height;
  const std::size_t p = std::size_t(W) * H;
  const std::size_t label_values = s.soft_labels ? p * std::size_t(s.label_count) : 0;
  // Images not selected (null): 0x0, their memory kept for a later solve that selects them.
  if (s.soft_labels) {
    result.soft_labels.width = W, result.soft_labels.height = H, result.soft_labels.count = s.label_count;
  } else {
    result.soft_labels.width = result.soft_labels.height = result.soft_labels.count = 0;
    result.soft_labels.data.clear();
  }
  if (s.scene_flow) {
    result.scene_flow.width = W, result.scene_flow.height = H, result.scene_flow.channels = 3;
  } else {
    result.scene_flow.width = result.scene_flow.height = 0;
    result.scene_flow.data.clear();
  }
  result.optical_flow.width = W, result.optical_flow.height = H, result.optical_flow.channels = 2;
  result.moved_depth.width = W, result.moved_depth.height = H, result.moved_depth.channels = 1;
  result.labels.width = W, result.labels.height = H, result.labels.channels = 1;
  result.occlusion.width = W, result.occlusion.height = H, result.occlusion.channels = 1;
  // A recycled result whose soft labels have this size (a stream at one size and label count): copied in 1 MiB chunks
  // on all threads into the memory as it is. Otherwise one task allocates and copies them in one pass (a resize
  // first would zero-fill all of it on this thread). The other images: copied in place where their size matches,
  // else allocated and copied, one task each.
  constexpr std::size_t kChunk = std::size_t(1) << 18;  // floats: 1 MiB
  const bool labels_in_place = s.soft_labels && result.soft_labels.data.size() == label_values;
  const int label_tasks = labels_in_place ? std::max(1, int((label_values + kChunk - 1) / kChunk)) : 1;
  const int tasks = label_tasks + 5;
  // The soft labels come down first (the others cannot arrive before them): this thread waits for them once, and
  // each of the other images is waited for by the one task that copies it. (Every chunk waiting for the soft
  // labels on its own thread made the outputs stage 2 ms slower for some pairs at 320x240 and 640x480.)
  std::vector<int> status(std::size_t(tasks), 0);
  const int labels_status = s.wait_for_image ? s.wait_for_image(0) : 0;
  auto copy = [](auto& data, const auto* from, std::size_t count) {
    if (data.size() == count)
      std::copy_n(from, count, data.begin());
    else
      data.assign(from, from + count);
  };
  auto fill = [&](int task) {
    const int image = task < label_tasks ? 0 : task - label_tasks + 1;
    if (image == 0)
      status[std::size_t(task)] = labels_status;
    else if (s.wait_for_image)
      status[std::size_t(task)] = s.wait_for_image(image);
    if (status[std::size_t(task)] != 0) return;
    switch (image) {
      case 0:
        if (!s.soft_labels) break;
        if (labels_in_place) {
          const std::size_t begin = std::size_t(task) * kChunk, end = std::min(label_values, begin + kChunk);
          std::copy(s.soft_labels + begin, s.soft_labels + end,
                    result.soft_labels.data.begin() + std::ptrdiff_t(begin));
        } else {
          result.soft_labels.data.assign(s.soft_labels, s.soft_labels + label_values);
        }
        break;
      case 1:
        if (s.scene_flow) copy(result.scene_flow.data, s.scene_flow, 3 * p);
        break;
      case 2: copy(result.optical_flow.data, s.optical_flow, 2 * p); break;
      case 3: copy(result.moved_depth.data, s.moved_depth, p); break;
      case 4: copy(result.labels.data, s.labels, p); break;
      default: copy(result.occlusion.data, s.occlusion, p); break;
    }
  };
  // Threads pay off where page faults and copies outweigh waking them: from about 2 MB of images (a 320x240 pair
  // with 16 labels spent 4.5 ms in the outputs stage with one thread, against 0.8 ms with 5 labels).
  const std::size_t bytes = label_values * 4 + p * ((s.scene_flow ? 3 * 4 : 0) + 2 * 4 + 4 + 4 + 1);
  const bool parallel = bytes >= (std::size_t(2) << 20);
#pragma omp parallel for schedule(dynamic, 1) if (parallel)
  for (int task = 0; task < tasks; ++task) fill(task);
  for (const int code : status)
    if (code != 0) {
      // A transfer failed: 0x0 images (their memory kept), not W x H ones holding whatever the copies left.
      for (auto* image : {&result.scene_flow, &result.optical_flow, &result.moved_depth}) {
        image->width = image->height = 0;
        image->data.clear();
      }
      result.soft_labels.width = result.soft_labels.height = result.soft_labels.count = 0;
      result.soft_labels.data.clear();
      result.labels.width = result.labels.height = 0;
      result.labels.data.clear();
      result.occlusion.width = result.occlusion.height = 0;
      result.occlusion.data.clear();
      return code;
    }
  return 0;
}

void stageInputFrames(const RgbdFrame& frame1, const RgbdFrame& frame2, float* staged) {
  const std::size_t plane = std::size_t(frame1.width()) * std::size_t(frame1.height());
  const std::vector<float>* inputs[4] = {&frame1.intensity.data, &frame1.depth.data, &frame2.intensity.data,
                                         &frame2.depth.data};
  const bool parallel = plane * 4 * sizeof(float) >= (std::size_t(2) << 20);
#ifdef _OPENMP
  const int threads = std::min(4, omp_get_max_threads());  // within Config::threads (ThreadCountScope)
#else
  const int threads = 1;
#endif
#pragma omp parallel for schedule(static, 1) num_threads(threads) if (parallel)
  for (int i = 0; i < 4; ++i) std::copy_n(inputs[i]->data(), plane, staged + std::size_t(i) * plane);
}

std::size_t stageCarryInputs(const Result& previous, bool dormant, unsigned char* staged) {
  const std::size_t pixels = previous.labels.data.size();
  const void* sources[4] = {previous.labels.data.data(), previous.optical_flow.data.data(),
                            previous.moved_depth.data.data(), previous.dormant_regions.data.data()};
  const std::size_t bytes[4] = {pixels * sizeof(std::int32_t), pixels * 2 * sizeof(float), pixels * sizeof(float),
                                dormant ? pixels * sizeof(std::int32_t) : 0};
  std::size_t offsets[4] = {0, 0, 0, 0};
  for (int i = 1; i < 4; ++i) offsets[i] = offsets[i - 1] + bytes[i - 1];
  if (staged) {
    // In slices of 256 KiB over the threads (one thread per image left the 2.4 MB of flow to one of them).
    constexpr std::size_t kSlice = std::size_t(256) << 10;
    std::vector<std::pair<int, std::size_t>> slices;  // (image, first byte)
    for (int i = 0; i < 4; ++i)
      for (std::size_t at = 0; at < bytes[i]; at += kSlice) slices.emplace_back(i, at);
    const bool parallel = offsets[3] + bytes[3] >= (std::size_t(2) << 20);
#pragma omp parallel for schedule(static) if (parallel)
    for (long j = 0; j < long(slices.size()); ++j) {
      const auto [i, at] = slices[std::size_t(j)];
      std::memcpy(staged + offsets[i] + at, static_cast<const unsigned char*>(sources[i]) + at,
                  std::min(kSlice, bytes[i] - at));
    }
  }
  return offsets[3] + bytes[3];
}

std::unique_ptr<SolveBackend> makeCpuSolveBackend() { return std::make_unique<CpuSolveBackend>(); }

#ifndef MCFLOW_HAVE_CUDA
bool cudaBackendAvailable(std::string* why, int) {
  if (why) *why = "this build of mc_flow has no CUDA backend (nvcc was not found when it was configured)";
  return false;
}
CudaCounters cudaCounters() { return CudaCounters(); }
bool cudaDeviceMemory(std::size_t*, std::size_t*) { return false; }

std::unique_ptr<SolveBackend> makeCudaSolveBackend(int) {
  throw BackendError("CUDA backend requested but this build has no CUDA (built without nvcc or MCFLOW_WITH_CUDA=OFF)");
}
#endif

Backend resolveBackend(Backend requested, std::string* note, int cuda_device) {
  std::string why;
  switch (requested) {
    case Backend::Cpu:
      if (note) *note = "cpu (requested)";
      return Backend::Cpu;
    case Backend::Cuda:
      if (!cudaBackendAvailable(&why, cuda_device))
        throw BackendError("CUDA backend requested but unavailable: " + why);
      if (note) *note = "cuda (requested, device " + std::to_string(cuda_device) + ")";
      return Backend::Cuda;
    case Backend::Auto:
    default:
      if (cudaBackendAvailable(&why, cuda_device)) {
        if (note) *note = "cuda (auto: GPU available, device " + std::to_string(cuda_device) + ")";
        return Backend::Cuda;
      }
      if (note) *note = "cpu (auto: " + why + ")";
      return Backend::Cpu;
  }
}

std::unique_ptr<SolveBackend> makeSolveBackend(Backend requested, std::string* note, int cuda_device) {
  return resolveBackend(requested, note, cuda_device) == Backend::Cuda ? makeCudaSolveBackend(cuda_device)
                                                                       : makeCpuSolveBackend();
}

}  // namespace mc_flow
