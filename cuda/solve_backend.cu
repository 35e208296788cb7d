// The CUDA backend of the solve's stages (src/core/solve_backend.cpp is the CPU one): the two frames go up once
// per pair, the pyramids are built on the device, and from there the labels, the dual variables, the data
// costs, the weights and the occlusion mask live on the device until the outputs come down in one transfer.
// Every stage runs on the backend's one stream; the host reads only what a decision needs (supports, moments,
// normal equations, energies, counts, and frame 1's points at the levels K-means and the warm start use).
#include <cuda_runtime.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cuda_check.h"
#include "device_stages.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/kmeans.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/solve_backend.h"

namespace mc_flow {

namespace cuda_detail {
DeviceTransform deviceTransform(const Vector6d& twist) {
  const Eigen::Matrix<float, 3, 4> T = se3Exp(twist).topRows<3>().cast<float>();
  DeviceTransform out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) out.m[r * 4 + c] = T(r, c);
  return out;
}
}  // namespace cuda_detail

namespace {

using cuda_detail::DeviceBuffer;
using cuda_detail::DeviceLevel;
using cuda_detail::PinnedBuffer;

// Result::device_outputs: one serial per filled result over all the process's backends, so that a result of another
// backend (or another solve) never matches the images a backend holds.
std::atomic<std::uint64_t> output_serials{0};

struct LevelBuffers {
  DeviceBuffer<float> points1, intensity1, depth1, intensity2, depth2, intensity_grad2, depth_grad2;
};

class CudaSolveBackend final : public SolveBackend {
 public:
  explicit CudaSolveBackend(int device)
      : device_(device),
        accumulator_(cuda_detail::makeDeviceMotionAccumulator(stream_.stream)),
        primal_dual_(cuda_detail::makeDevicePrimalDual(stream_.stream)) {}

  Backend kind() const override { return Backend::Cuda; }
  void activate() override { MCFLOW_CUDA_CHECK(cudaSetDevice(device_)); }

  void buildPyramids(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, int levels,
                     const Config& config) override {
    const int W = frame1.width(), H = frame1.height();
    if (levels < 1 || frame2.width() != W || frame2.height() != H || !frame1.depth.sameSize(frame1.intensity) ||
        !frame2.depth.sameSize(frame2.intensity) || W < 1 || H < 1)
      throw InputError("CUDA backend buildPyramids: frames " + imageSizeText(frame1.intensity) + " / " +
                       imageSizeText(frame1.depth) + " and " + imageSizeText(frame2.intensity) + " / " +
                       imageSizeText(frame2.depth) + ", " + std::to_string(levels) + " levels");
    K_ = K;
    while (int(buffers_.size()) < levels) buffers_.push_back(std::make_unique<LevelBuffers>());
    levels_.assign(std::size_t(levels), DeviceLevel{});
    std::vector<cuda_detail::DevicePyramidLevel> pyramid1(static_cast<std::size_t>(levels)),
        pyramid2(static_cast<std::size_t>(levels));
    for (int l = 0; l < levels; ++l) {
      const int w = pyramidLevelExtent(W, l), h = pyramidLevelExtent(H, l);
      const std::size_t plane = std::size_t(w) * h;
      LevelBuffers& d = *buffers_[std::size_t(l)];
      for (DeviceBuffer<float>* b : {&d.intensity1, &d.depth1, &d.intensity2, &d.depth2}) b->reserve(plane);
      d.points1.reserve(plane * 3);
      d.intensity_grad2.reserve(plane * 2);
      d.depth_grad2.reserve(plane * 2);
      const Intrinsics Kl = K.scaled(std::ldexp(1.0, -l));
      cuda_detail::DevicePyramidLevel& a = pyramid1[std::size_t(l)];
      a.width = w, a.height = h, a.intrinsics = Kl;
      a.intensity = d.intensity1.get(), a.depth = d.depth1.get(), a.points = d.points1.get();
      cuda_detail::DevicePyramidLevel& b = pyramid2[std::size_t(l)];
      b.width = w, b.height = h, b.intrinsics = Kl;
      b.intensity = d.intensity2.get(), b.depth = d.depth2.get();
      b.intensity_grad = d.intensity_grad2.get(), b.depth_grad = d.depth_grad2.get();
      DeviceLevel& v = levels_[std::size_t(l)];
      v.width = w;
      v.height = h;
      v.intrinsics = Kl;
      v.points1 = {d.points1.get(), w, h, 3};
      v.intensity1 = {d.intensity1.get(), w, h, 1};
      v.intensity2 = {d.intensity2.get(), w, h, 1};
      v.depth2 = {d.depth2.get(), w, h, 1};
      v.intensity_grad2 = {d.intensity_grad2.get(), w, h, 2};
      v.depth_grad2 = {d.depth_grad2.get(), w, h, 2};
    }
    // The inputs go up through one page-locked staging buffer, then every level is built on the device.
    const std::size_t plane = std::size_t(W) * H;
    float* staged = staged_frames_.reserve(plane * 4);
    stageInputFrames(frame1, frame2, staged);
    float* targets[4] = {pyramid1[0].intensity, pyramid1[0].depth, pyramid2[0].intensity, pyramid2[0].depth};
    for (int i = 0; i < 4; ++i)
      MCFLOW_CUDA_CHECK(cudaMemcpyAsync(targets[i], staged + std::size_t(i) * plane, plane * sizeof(float),
                                        cudaMemcpyHostToDevice, stream_.stream));
    valid_counts_device_.reserve(std::size_t(levels));
    cuda_detail::launchBuildPyramid(pyramid1, config, valid_counts_device_.get(), stream_.stream);
    cuda_detail::launchBuildPyramid(pyramid2, config, nullptr, stream_.stream);
    valid_counts_.assign(std::size_t(levels), 0);
    download(valid_counts_.data(), valid_counts_device_.get(), std::size_t(levels), staged_ints_);
    // The host copies keep their memory across pairs; they are downloaded again when asked for.
    if (host_points_.size() < std::size_t(levels)) host_points_.resize(std::size_t(levels));
    host_points_current_.assign(std::size_t(levels), false);
    count_ = 0;
    level_ = 0;
    weights_level_ = -1;
    carried_held_ = false;
  }

  const ImageF& framePoints(int level) override {
    const DeviceLevel& L = levelAt(level);
    ImageF& points = host_points_[std::size_t(level)];
    if (!host_points_current_[std::size_t(level)]) {
      if (!points.sameSize(L.width, L.height) || points.channels != 3) points = ImageF(L.width, L.height, 3);
      download(points.data.data(), L.points1.data, points.data.size(), staged_floats_);
      host_points_current_[std::size_t(level)] = true;
    }
    return points;
  }

  const std::vector<int>& validCounts() const override { return valid_counts_; }

  CarriedSegments carrySegments(const Result& previous, const ImageF& /*frame1_depth: level 0 is on the device*/,
                                int label_level, const Config& config) override {
    const DeviceLevel& L0 = levelAt(0);
    const int W = L0.width, H = L0.height;
    const bool dormant = !previous.dormant_ids.empty();
    checkCarryInputs(previous.labels, previous, W, H);
    if (dormant) checkCarryInputs(previous.dormant_regions, previous, W, H);
    const DeviceLevel* label_level_images = label_level >= 0 ? &levelAt(label_level) : nullptr;  // throws if absent
    const int scale = label_level >= 0 ? 1 << label_level : 1;
    if (label_level_images && (label_level_images->width * scale > W || label_level_images->height * scale > H))
      throw InputError("CUDA carried labels: a " + std::to_string(W) + "x" + std::to_string(H) +
                       " id image cannot cover level " + std::to_string(label_level) + " (" +
                       std::to_string(label_level_images->width) + "x" + std::to_string(label_level_images->height) +
                       ") at scale " + std::to_string(scale));
    const std::size_t pixels = std::size_t(W) * std::size_t(H);
    cudaStream_t s = stream_.stream;
    const int* in_ids = nullptr;
    const float* in_flow = nullptr;
    const float* in_moved_depth = nullptr;
    const int* in_dormant = nullptr;
    const int motion_labels = int(previous.segments.size());
    // The same images in the same memory: a copy of the result (which a caller may have edited) has its own, and is
    // uploaded.
    const bool same_images = previous.labels.data.data() == outputs_labels_memory_ &&
                             previous.optical_flow.data.data() == outputs_flow_memory_ &&
                             previous.moved_depth.data.data() == outputs_moved_depth_memory_;
    if (previous.device_outputs != 0 && previous.device_outputs == outputs_serial_ && same_images &&
        W == outputs_width_ && H == outputs_height_ && motion_labels == outputs_motion_labels_) {
      // The previous result is this backend's latest: its flow and moved depth are still on the device, its ids are its
      // output labels through a table (label index + 1 -> id). Up: the table and the dormant regions (a 640x480 pair's
      // 4.8 MB staged and uploaded took about 0.7 ms, H100 machine).
      const std::size_t table = std::size_t(motion_labels) + 1, dormant_values = dormant ? pixels : 0;
      int* staged_in = reinterpret_cast<int*>(staged_carry_in_.reserve((table + dormant_values) * sizeof(int)));
      staged_in[0] = 0;
      for (int i = 0; i < motion_labels; ++i) staged_in[i + 1] = previous.segments[std::size_t(i)].id;
      if (dormant) std::copy_n(previous.dormant_regions.data.data(), pixels, staged_in + table);
      carry_in_.reserve((pixels + table + dormant_values) * sizeof(int));
      int* device_ints = reinterpret_cast<int*>(carry_in_.get());
      MCFLOW_CUDA_CHECK(cudaMemcpyAsync(device_ints + pixels, staged_in, (table + dormant_values) * sizeof(int),
                                        cudaMemcpyHostToDevice, s));
      cuda_detail::carry_bytes_uploaded.fetch_add((table + dormant_values) * sizeof(int), std::memory_order_relaxed);
      cuda_detail::launchIdsOfLabels(ids_.get(), device_ints + pixels, motion_labels, pixels, device_ints, s);
      in_ids = device_ints;
      in_flow = optical_flow_.get();
      in_moved_depth = moved_depth_.get();
      in_dormant = device_ints + pixels + table;
    } else {
      // Up, through the page-locked buffer in one copy: the previous pair's ids, optical flow and moved depth (and
      // dormant regions); its frame 1 was this pair's. (From pageable memory a 640x480 pair's 4.8 MB took 0.8 ms, H100
      // machine.)
      const std::size_t in_bytes = stageCarryInputs(previous, dormant, nullptr);
      unsigned char* staged_in = staged_carry_in_.reserve(in_bytes);
      stageCarryInputs(previous, dormant, staged_in);
      carry_in_.reserve(in_bytes);
      MCFLOW_CUDA_CHECK(cudaMemcpyAsync(carry_in_.get(), staged_in, in_bytes, cudaMemcpyHostToDevice, s));
      cuda_detail::carry_bytes_uploaded.fetch_add(in_bytes, std::memory_order_relaxed);
      in_ids = reinterpret_cast<const int*>(carry_in_.get());
      in_flow = reinterpret_cast<const float*>(in_ids + pixels);
      in_moved_depth = in_flow + 2 * pixels;
      in_dormant = reinterpret_cast<const int*>(in_moved_depth + pixels);
    }
    // The next reuse of staged_carry_in_ is after this call's wait below.
    // The carries, into consecutive planes of carry_out_: the ids, the dormant regions, then the level's majority ids.
    const bool majority_on_device = label_level_images && scale <= cuda_detail::kMaxMajorityScale;
    const std::size_t level_pixels =
        majority_on_device ? std::size_t(label_level_images->width) * std::size_t(label_level_images->height) : 0;
    const std::size_t planes = dormant ? 2 : 1, out_values = planes * pixels + level_pixels;
    carry_winner_.reserve(pixels);
    carry_kept_.reserve(pixels);
    carry_out_.reserve(out_values);
    const float* depth = buffers_[0]->depth1.get();  // cleaned by the pyramid (0 = none)
    for (std::size_t plane = 0; plane < planes; ++plane)
      cuda_detail::launchCarryIds(plane == 0 ? in_ids : in_dormant, in_flow, in_moved_depth, depth, W, H,
                                  config.warm_depth_tolerance, carry_winner_.get(), carry_kept_.get(),
                                  carry_out_.get() + plane * pixels, s);
    if (majority_on_device)
      cuda_detail::launchCarriedMajority(carry_out_.get(), W, label_level_images->points1, scale,
                                         carry_out_.get() + planes * pixels, s);
    // Down in one wait.
    int* staged = staged_carry_out_.reserve(out_values);
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(staged, carry_out_.get(), out_values * sizeof(int), cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    CarriedSegments out;
    auto image = [&](ImageI32& to, const int* from) {
      to.width = W;
      to.height = H;
      to.channels = 1;
      to.data.assign(from, from + pixels);
    };
    image(out.ids, staged);
    if (dormant) image(out.dormant, staged + pixels);
    if (majority_on_device) {
      const DeviceLevel& L = *label_level_images;
      ImageI32 majority(L.width, L.height, 1);
      std::copy_n(staged + planes * pixels, level_pixels, majority.data.data());
      out.labels = carriedLabelsFromMajority(majority);
    } else if (label_level_images) {  // coarser than the device's majority takes: on the host
      out.labels = carriedLabelsAtLevel(out.ids, framePoints(label_level), scale);
    }
    return out;
  }

  void initialiseLabels(int level, const ImageI32& hard, int motion_labels) override {
    const DeviceLevel& L = levelAt(level);
    validateHardLabels(hard, motion_labels, L.width, L.height);
    uploadHardLabels(hard);
    labelsFromHardLabels(level, motion_labels);
    // The staging buffer is reused by the next small transfer: wait for this one.
    MCFLOW_CUDA_WAIT(stream_.stream);
  }

  std::vector<Eigen::Vector3f> kmeansCentres(int level, int k, int max_iterations, double tolerance_m,
                                             unsigned seed) override {
    // Outside what the kernel argument holds (Config caps initial_labels at its size), or refused: the host's.
    if (k < 1 || k > cuda_detail::KMeansCentres::kMax || max_iterations < 0)
      return SolveBackend::kmeansCentres(level, k, max_iterations, tolerance_m, seed);
    const cuda_detail::KMeansOutcome outcome =
        runKMeans(levelAt(level), k, max_iterations, tolerance_m, seed, nullptr, 0);
    std::vector<Eigen::Vector3f> centres(std::size_t(outcome.centres.count));
    for (std::size_t c = 0; c < centres.size(); ++c)
      centres[c] =
          Eigen::Vector3f(outcome.centres.xyz[3 * c], outcome.centres.xyz[3 * c + 1], outcome.centres.xyz[3 * c + 2]);
    return centres;
  }

  void initialiseLabelsFromCentres(int level, const std::vector<Eigen::Vector3f>& centres) override {
    // More centres than a kernel argument holds (Config caps initial_labels at its size): the host's assignment.
    if (int(centres.size()) > cuda_detail::KMeansCentres::kMax)
      return SolveBackend::initialiseLabelsFromCentres(level, centres);
    if (centres.empty()) throw InputError("initial labels from K-means: no centre given");
    const DeviceLevel& L = levelAt(level);
    cuda_detail::KMeansCentres argument;
    argument.count = int(centres.size());
    for (std::size_t c = 0; c < centres.size(); ++c)
      for (int k = 0; k < 3; ++k) argument.xyz[3 * c + std::size_t(k)] = centres[c](k);
    hard_labels_.reserve(std::size_t(L.width) * L.height);
    cuda_detail::launchNearestCentreLabels(L.points1, argument, hard_labels_.get(), stream_.stream);
    labelsFromHardLabels(level, int(centres.size()));
  }

  int initialiseLabelsWithUncoveredClusters(int level, const ImageI32& hard, int first_new, int clusters,
                                            const Config& config) override {
    // Outside what the kernel argument holds (Config caps initial_labels at its size), or refused: the host's.
    if (clusters < 1 || clusters > cuda_detail::KMeansCentres::kMax || config.kmeans_max_iterations < 0)
      return SolveBackend::initialiseLabelsWithUncoveredClusters(level, hard, first_new, clusters, config);
    const DeviceLevel& L = levelAt(level);
    validateCarriedHardLabels(hard, first_new, L.width, L.height);
    uploadHardLabels(hard);
    // The K-means writes the uncovered pixels' labels into the uploaded ones; its wait covers the upload too.
    const int kept = runKMeans(L, clusters, config.kmeans_max_iterations, config.kmeans_tolerance, config.seed,
                               hard_labels_.get(), first_new)
                         .centres.count;
    requireMotionLabels(first_new + kept);  // as the host's initialiseLabels
    labelsFromHardLabels(level, first_new + kept);
    return kept;
  }

  void holdCarriedLabels(int carried_labels) override {
    carried_held_ = false;
    carried_slot_ = 0;  // buffer 0 at the label level, buffer 1 at the level moved to: no regrowth from pair to pair
    if (carried_labels <= 0 || count_ == 0) return;
    if (level_ != hard_level_)
      throw InputError("CUDA backend: holdCarriedLabels must follow initialiseLabels (labels at level " +
                       std::to_string(level_) + ", initial labels at level " + std::to_string(hard_level_) + ")");
    const DeviceLevel& L = levels_[std::size_t(level_)];
    carried_[carried_slot_].reserve(plane());
    cuda_detail::launchCarriedFromHard(L.points1, hard_labels_.get(), std::min(carried_labels, count_ - 1), carried(),
                                       stream_.stream);
    carried_held_ = true;
  }

  void moveLabels(int level) override {
    const DeviceLevel& to = levelAt(level);
    if (level != level_) {
      int w = levels_[std::size_t(level_)].width, h = levels_[std::size_t(level_)].height;
      if (carried_held_) {
        DeviceBuffer<int>& moved = carried_[1 - carried_slot_];
        moved.reserve(std::size_t(to.width) * to.height);
        cuda_detail::launchResampleMask(carried(), w, h, moved.get(), to.width, to.height, stream_.stream);
        carried_slot_ = 1 - carried_slot_;
      }
      reserveLabels(std::size_t(to.width) * to.height, count_);  // may move the labels to the other buffer
      if (level < level_) {
        cuda_detail::launchUpsampleLabels(labels(), w, h, count_, scratch(), to.width, to.height, stream_.stream);
        swapLabels();
      } else {
        for (int l = level_ + 1; l <= level; ++l) {
          const DeviceLevel& next = levels_[std::size_t(l)];
          cuda_detail::launchDownsampleLabels(labels(), w, h, count_, scratch(), next.width, next.height,
                                              stream_.stream);
          swapLabels();
          w = next.width;
          h = next.height;
        }
      }
      level_ = level;
    }
    clearOcclusionAndDual();
  }

  MotionAccumulator& motionAccumulator(int level, MotionLabels which, bool use_occlusion,
                                       const Config& config) override {
    const DeviceLevel& L = levelAt(level);
    const std::size_t level_plane = std::size_t(L.width) * L.height;
    const float* bound_labels = nullptr;
    int bound_count = 0;
    cudaStream_t s = stream_.stream;
    if (which == MotionLabels::AllValidAsOne) {
      level_labels_[0].reserve(level_plane * 2);
      cuda_detail::launchAllValidAsOne(L.points1, level_labels_[0].get(), s);
      bound_labels = level_labels_[0].get();
      bound_count = 2;
    } else if (level == level_) {
      bound_labels = labels();
      bound_count = count_;
    } else {
      bound_count = count_;
      const DeviceLevel& from = levels_[std::size_t(level_)];
      if (level < level_) {
        level_labels_[0].reserve(level_plane * std::size_t(count_));
        cuda_detail::launchUpsampleLabels(labels(), from.width, from.height, count_, level_labels_[0].get(), L.width,
                                          L.height, s);
        bound_labels = level_labels_[0].get();
      } else {
        const float* src = labels();
        int w = from.width, h = from.height, slot = 0;
        for (int l = level_ + 1; l <= level; ++l) {
          const DeviceLevel& next = levels_[std::size_t(l)];
          level_labels_[slot].reserve(std::size_t(next.width) * next.height * std::size_t(count_));
          cuda_detail::launchDownsampleLabels(src, w, h, count_, level_labels_[slot].get(), next.width, next.height, s);
          src = level_labels_[slot].get();
          slot = 1 - slot;
          w = next.width;
          h = next.height;
        }
        bound_labels = src;
      }
    }
    const std::uint8_t* bound_occlusion = nullptr;
    if (use_occlusion) {
      if (level == level_) {
        bound_occlusion = occlusion_.get();
      } else {
        level_occlusion_.reserve(level_plane);
        const DeviceLevel& from = levels_[std::size_t(level_)];
        cuda_detail::launchResampleMask(occlusion_.get(), from.width, from.height, level_occlusion_.get(), L.width,
                                        L.height, s);
        bound_occlusion = level_occlusion_.get();
      }
    }
    accumulator_->bind(L, bound_labels, bound_count, bound_occlusion, config);
    return *accumulator_;
  }

  void updateOcclusion(const std::vector<Vector6d>& twists, const Config& config) override {
    requireTwists("updateOcclusion", twists);
    const DeviceLevel& L = levels_[std::size_t(level_)];
    uploadMotions(twists);
    const std::size_t p = plane();
    counts_.reserve(p);
    targets_.reserve(p);
    warped_z_.reserve(p);
    cuda_detail::launchOcclusion(L, labels(), count_, motions_.get(), config, counts_.get(), targets_.get(),
                                 warped_z_.get(), occlusion_.get(), stream_.stream);
  }

  LabelStepStats labelStep(const std::vector<Vector6d>& twists, bool use_occlusion, int iterations, double tolerance,
                           const Config& config) override {
    requireTwists("labelStep", twists);
    const DeviceLevel& L = levels_[std::size_t(level_)];
    const std::size_t p = plane();
    cudaStream_t s = stream_.stream;
    if (weights_level_ != level_) {
      weight_x_.reserve(p);
      weight_y_.reserve(p);
      cuda_detail::launchGeometricWeights(L, config.min_geometric_weight, weight_x_.get(), weight_y_.get(), s);
      weights_level_ = level_;
    }
    const std::size_t n = twists.size();
    auto* staged = staged_transforms_.reserve(n);
    for (std::size_t i = 0; i < n; ++i) staged[i] = cuda_detail::deviceTransform(twists[i]);
    transforms_.reserve(std::max<std::size_t>(n, 1));
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(transforms_.get(), staged, n * sizeof(cuda_detail::DeviceTransform),
                                      cudaMemcpyHostToDevice, s));
    data_cost_.reserve(p * std::size_t(count_));
    outlier_only_.reserve(p);
    cuda_detail::launchDataCosts(L, transforms_.get(), int(n), use_occlusion ? occlusion_.get() : nullptr, config,
                                 data_cost_.get(), outlier_only_.get(), s);
    if (carried_held_)
      cuda_detail::launchAddSwitchingCost(carried(), float(config.warm_switch_cost), p, count_, outlier_only_.get(),
                                          data_cost_.get(), s);
    const std::size_t values = p * std::size_t(count_);
    before_.reserve(values);
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(before_.get(), labels(), values * sizeof(float), cudaMemcpyDeviceToDevice, s));

    const cuda_detail::DeviceLabelProblem problem{L.width,
                                                  L.height,
                                                  count_,
                                                  data_cost_.get(),
                                                  weight_x_.get(),
                                                  weight_y_.get(),
                                                  outlier_only_.get(),
                                                  config.regularizer,
                                                  config.lambda()};
    const LabelStats ls = primal_dual_->run(problem, labels(), dual_.get(), iterations, tolerance);

    scalar_.reserve(2);
    cuda_detail::launchAbsoluteChange(labels(), before_.get(), values, partials_, scalar_.get(), s);
    if (carried_held_)
      cuda_detail::launchSwitchingShare(labels(), carried(), outlier_only_.get(), p, partials_, scalar_.get() + 1, s);
    double* sums = staged_doubles_.reserve(2);
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(sums, scalar_.get(), (carried_held_ ? 2 : 1) * sizeof(double), cudaMemcpyDeviceToHost, s));
    MCFLOW_CUDA_WAIT(s);
    LabelStepStats out;
    out.iterations = ls.iterations;
    out.energy = ls.energy;  // E(u) of eq. 4, without the switching cost
    if (carried_held_) out.energy -= double(float(config.warm_switch_cost)) * sums[1];
    out.mean_change = sums[0] / double(p);
    return out;
  }

  void outputs(const std::vector<Vector6d>& twists, const Config& config, const OutputSelection& selection,
               Result& result) override {
    requireTwists("outputs", twists);
    outputs_serial_ = 0;  // the device's images are being replaced: no result matches them until this one is filled
    moveLabels(0);        // carried up from the processing level; clears the occlusion mask
    DeviceLevel L = levels_[0];
    L.intrinsics = K_;  // the input's, as given (K.scaled(1) may differ in the last bit), as the CPU backend
    const int W = L.width, H = L.height, n = count_ - 1;
    const std::size_t p = plane();
    cudaStream_t s = stream_.stream;
    uploadMotions(twists);
    scene_flow_.reserve(p * 3);
    optical_flow_.reserve(p * 2);
    moved_depth_.reserve(p);
    ids_.reserve(p);
    cuda_detail::launchSceneFlowOutputs(L.points1, labels(), count_, motions_.get(), K_, scene_flow_.get(),
                                        optical_flow_.get(), moved_depth_.get(), ids_.get(), s);
    if (config.detect_occlusions) {
      counts_.reserve(p);
      targets_.reserve(p);
      warped_z_.reserve(p);
      cuda_detail::launchOcclusion(L, labels(), count_, motions_.get(), config, counts_.get(), targets_.get(),
                                   warped_z_.get(), occlusion_.get(), s);
    }
    // Per label: the u-weighted point sums and sum u over the valid pixels, which is the support (the pixels
    // without depth were just moved to the outlier label).
    scalar_.reserve(std::size_t(std::max(1, 4 * n)));
    cuda_detail::launchLabelCentroidSums(labels(), L.points1, n, partials_, scalar_.get(), s);

    // Every image down into one page-locked buffer per type, an event after each: the host copies an image into the
    // Result as soon as it has arrived, while the next ones are on their way.
    const std::size_t label_values = p * std::size_t(count_);
    float* floats = staged_floats_.reserve(label_values + p * 6);
    float* const staged_labels = floats;
    float* const staged_scene = staged_labels + label_values;
    float* const staged_optical = staged_scene + p * 3;
    float* const staged_moved = staged_optical + p * 2;
    int* staged_ids = staged_ints_.reserve(p);
    std::uint8_t* staged_occlusion = staged_bytes_.reserve(p);
    double* staged_sums = staged_doubles_.reserve(std::size_t(std::max(1, 4 * n)));
    int image = 0;
    // An image not selected is not copied; its event is still recorded (fillOutputImages waits for every image).
    auto down = [&](void* to, const void* from, std::size_t bytes, bool selected = true) {
      if (selected) MCFLOW_CUDA_CHECK(cudaMemcpyAsync(to, from, bytes, cudaMemcpyDeviceToHost, s));
      MCFLOW_CUDA_CHECK(cudaEventRecord(image_downloaded_[image++].event, s));
    };
    // In fillOutputImages' order of images.
    down(staged_labels, labels(), label_values * sizeof(float), selection.soft_labels);
    down(staged_scene, scene_flow_.get(), p * 3 * sizeof(float), selection.scene_flow);
    down(staged_optical, optical_flow_.get(), p * 2 * sizeof(float));
    down(staged_moved, moved_depth_.get(), p * sizeof(float));
    down(staged_ids, ids_.get(), p * sizeof(int));
    down(staged_occlusion, occlusion_.get(), p);
    if (n > 0)
      MCFLOW_CUDA_CHECK(
          cudaMemcpyAsync(staged_sums, scalar_.get(), std::size_t(4 * n) * sizeof(double), cudaMemcpyDeviceToHost, s));

    // The images in StagedOutputs' order; each waited for on OpenMP threads, which may not have used this backend's
    // device yet.
    StagedOutputs staged{W,
                         H,
                         count_,
                         selection.soft_labels ? staged_labels : nullptr,
                         selection.scene_flow ? staged_scene : nullptr,
                         staged_optical,
                         staged_moved,
                         staged_ids,
                         staged_occlusion,
                         {}};
    staged.wait_for_image = [this](int i) {
      cudaError_t e = cudaSetDevice(device_);
      if (e == cudaSuccess) e = cudaEventSynchronize(image_downloaded_[i].event);
      return int(e);
    };
    // Checked here, not inside the OpenMP threads: they must not throw.
    MCFLOW_CUDA_CHECK(static_cast<cudaError_t>(fillOutputImages(staged, result)));
    MCFLOW_CUDA_WAIT(s);  // the label sums
    result.segments.assign(std::size_t(n), Segment());
    for (int i = 0; i < n; ++i) {
      Segment& segment = result.segments[std::size_t(i)];
      const double* c = staged_sums + 4 * i;
      segment.support = c[3];
      segment.centroid = c[3] > 0 ? Eigen::Vector3d(c[0] / c[3], c[1] / c[3], c[2] / c[3]) : Eigen::Vector3d::Zero();
    }
    // The ids, optical flow and moved depth stay on the device for the next pair's carry (Result::device_outputs).
    outputs_serial_ = output_serials.fetch_add(1, std::memory_order_relaxed) + 1;
    outputs_width_ = W;
    outputs_height_ = H;
    outputs_motion_labels_ = n;
    outputs_labels_memory_ = result.labels.data.data();
    outputs_flow_memory_ = result.optical_flow.data.data();
    outputs_moved_depth_memory_ = result.moved_depth.data.data();
    result.device_outputs = outputs_serial_;
  }

  SoftLabels downloadLabels() override {
    const DeviceLevel& L = levels_[std::size_t(level_)];
    SoftLabels u(L.width, L.height, count_, 0.f);
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(u.data.data(), labels(), u.data.size() * sizeof(float), cudaMemcpyDeviceToHost,
                                      stream_.stream));
    MCFLOW_CUDA_WAIT(stream_.stream);
    return u;
  }

  // ---- LabelStore
  int labelCount() const override { return count_; }

  std::vector<double> supports() override {
    const int n = count_ - 1;
    std::vector<double> out(std::size_t(std::max(0, n)));
    if (n <= 0) return out;
    scalar_.reserve(std::size_t(n));
    cuda_detail::launchLabelSupports(labels(), plane(), n, partials_, scalar_.get(), stream_.stream);
    download(out.data(), scalar_.get(), std::size_t(n), staged_doubles_);
    return out;
  }

  void remap(const std::vector<int>& target, int new_count) override {
    validateRemap(target, count_, new_count);
    const std::size_t p = plane();
    reserveLabels(p, std::max(count_, new_count));
    cuda_detail::launchRemapLabels(labels(), p, count_, target.data(), new_count, scratch(), stream_.stream);
    swapLabels();
    if (carried_held_) cuda_detail::launchRemapCarried(carried(), p, count_, target.data(), new_count, stream_.stream);
    if (new_count != count_) zeroDual(p, new_count);
    count_ = new_count;
  }

  std::vector<LabelMoments> ownedMoments() override {
    const int n = count_ - 1;
    std::vector<LabelMoments> out(std::size_t(std::max(0, n)));
    if (n <= 0) return out;
    std::vector<double> values(std::size_t(n) * 10);
    scalar_.reserve(values.size());
    cuda_detail::launchOwnedMoments(labels(), levels_[std::size_t(level_)].points1, n, partials_, scalar_.get(),
                                    stream_.stream);
    download(values.data(), scalar_.get(), values.size(), staged_doubles_);
    for (int i = 0; i < n; ++i) {
      const double* v = values.data() + 10 * i;
      LabelMoments& m = out[std::size_t(i)];
      m.count = v[0];
      m.sum = Eigen::Vector3d(v[1], v[2], v[3]);
      m.outer << v[4], v[5], v[6], v[5], v[7], v[8], v[6], v[8], v[9];
    }
    return out;
  }

  CutTrial trialCuts(const std::vector<LabelCut>& cuts, const std::vector<Vector6d>& twists, bool use_occlusion,
                     const Config& config) override {
    const int m = int(cuts.size());
    CutTrial trial;
    trial.moved.assign(std::size_t(m), 0.0);
    if (int(twists.size()) != count_ - 1 + m)
      throw InputError("CUDA backend trialCuts: " + std::to_string(twists.size()) + " twists for " +
                       std::to_string(count_ - 1 + m) + " motion labels");
    // The trial labelling goes to the scratch buffer; the labels stay as they are.
    cutInto(cuts, use_occlusion, config);
    const DeviceLevel& L = levels_[std::size_t(level_)];
    accumulator_->bind(L, scratch(), count_ + m, use_occlusion ? occlusion_.get() : nullptr, config);
    MotionNormalEquations equations;
    accumulator_->accumulateLabelBlocks(twists, equations);
    trial.model = costModelFromEquations(equations, count_ - 1 + m);
    std::vector<unsigned long long> counts(static_cast<std::size_t>(m));
    if (m > 0) download(counts.data(), moved_.get(), counts.size(), staged_counts_);
    for (int c = 0; c < m; ++c) trial.moved[std::size_t(c)] = double(counts[std::size_t(c)]);
    return trial;
  }

  void applyCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) override {
    if (cuts.empty()) return;
    cutInto(cuts, use_occlusion, config);
    swapLabels();
    // A cut's pixels are free of the switching cost: the label step decides between the halves on the data alone.
    if (carried_held_)
      cuda_detail::launchReleaseCutPixels(labels(), plane(), count_ - 1, int(cuts.size()), carried(), stream_.stream);
    count_ += int(cuts.size());
    zeroDual(plane(), count_);
  }

  bool refitUnionsWhereTheSumsAre(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& groups,
                                  const std::vector<int>& batches, const std::vector<Vector6d>& starts, int iterations,
                                  bool use_occlusion, const Config& config, std::vector<UnionFit>& fits) override {
    requireTwists("refitUnions", twists);
    motionAccumulator(level_, MotionLabels::Current, use_occlusion, config);  // binds accumulator_ to the labels
    accumulator_->refitUnions(twists, groups, batches, starts, iterations, config, fits);
    return true;
  }

  bool refitPairsWhereTheSumsAre(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& pairs,
                                 const std::vector<int>& batches, const std::vector<double>& own_cost, int iterations,
                                 bool use_occlusion, const Config& config, std::vector<UnionFit>& fits) override {
    requireTwists("refitPairs", twists);
    motionAccumulator(level_, MotionLabels::Current, use_occlusion, config);  // binds accumulator_ to the labels
    return accumulator_->refitPairs(twists, pairs, batches, own_cost, iterations, config, fits);
  }

  std::vector<LabelCostModel> costModels(const std::vector<std::vector<Vector6d>>& twist_sets, bool use_occlusion,
                                         const Config& config) override {
    for (const std::vector<Vector6d>& twists : twist_sets) requireTwists("costModels", twists);
    motionAccumulator(level_, MotionLabels::Current, use_occlusion, config);  // binds accumulator_ to the labels
    std::vector<MotionNormalEquations> equations;
    accumulator_->accumulateLabelBlockSets(twist_sets, equations);
    std::vector<LabelCostModel> models;
    for (const MotionNormalEquations& e : equations) models.push_back(costModelFromEquations(e, count_ - 1));
    return models;
  }

  LabelCostModel costModel(const std::vector<Vector6d>& twists, bool use_occlusion, const Config& config) override {
    requireTwists("costModel", twists);
    MotionAccumulator& accumulator = motionAccumulator(level_, MotionLabels::Current, use_occlusion, config);
    MotionNormalEquations equations;
    accumulator.accumulateLabelBlocks(twists, equations);
    return costModelFromEquations(equations, count_ - 1);
  }

 private:
  const DeviceLevel& levelAt(int level) const {
    if (level < 0 || level >= int(levels_.size()))
      throw InputError("CUDA backend: pyramid level " + std::to_string(level) + " outside [0, " +
                       std::to_string(levels_.size()) + ")");
    return levels_[std::size_t(level)];
  }
  std::size_t plane() const {
    const DeviceLevel& L = levels_[std::size_t(level_)];
    return std::size_t(L.width) * L.height;
  }
  void requireTwists(const char* what, const std::vector<Vector6d>& twists) const {
    if (int(twists.size()) != count_ - 1)
      throw InputError(std::string("CUDA backend ") + what + ": " + std::to_string(twists.size()) + " twists for " +
                       std::to_string(count_ - 1) + " motion labels");
  }

  float* labels() { return label_buffers_[current_].get(); }
  float* scratch() { return label_buffers_[1 - current_].get(); }
  void swapLabels() { current_ = 1 - current_; }
  void reserveLabels(std::size_t p, int count) {
    const std::size_t values = p * std::size_t(count);
    if (values > label_buffers_[current_].capacity()) {
      // Growing loses the contents: grow the other buffer, keep the labels there, and make it the current one.
      label_buffers_[1 - current_].reserve(values);
      if (count_ > 0)
        MCFLOW_CUDA_CHECK(cudaMemcpyAsync(scratch(), labels(), plane() * std::size_t(count_) * sizeof(float),
                                          cudaMemcpyDeviceToDevice, stream_.stream));
      swapLabels();
    }
    label_buffers_[1 - current_].reserve(values);  // the scratch buffer
  }
  // Writes the labels with `cuts` applied into the scratch buffer and counts the moved pixels into moved_.
  void cutInto(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) {
    const int m = int(cuts.size());
    if (m == 0) return;
    for (const LabelCut& c : cuts)
      if (c.parent < 0 || c.parent >= count_ - 1)
        throw InputError("label cut: parent " + std::to_string(c.parent) + " is not a motion label (count " +
                         std::to_string(count_) + ")");
    constexpr int kValues = cuda_detail::kCutValues;
    double* staged = staged_doubles_.reserve(std::size_t(m) * kValues);
    std::vector<Vector6d> judged_at;  // the cuts by the data: one plane of data costs each, under its twist
    for (int c = 0; c < m; ++c) {
      const LabelCut& cut = cuts[std::size_t(c)];
      double* v = staged + kValues * c;
      v[0] = cut.parent;
      for (int k = 0; k < 3; ++k) {
        v[1 + k] = cut.centre(k);
        v[4 + k] = cut.axis(k);
      }
      v[7] = cut.cost_above > 0 ? cut.cost_above : 0.0;
      v[8] = cut.cost_above > 0 ? double(judged_at.size()) : 0.0;
      if (cut.cost_above > 0) judged_at.push_back(cut.judged_at);
    }
    cuts_.reserve(std::size_t(m) * kValues);
    moved_.reserve(std::size_t(m));
    cudaStream_t s = stream_.stream;
    const DeviceLevel& L = levels_[std::size_t(level_)];
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(cuts_.get(), staged, std::size_t(m) * kValues * sizeof(double), cudaMemcpyHostToDevice, s));
    if (!judged_at.empty()) {
      const std::size_t j = judged_at.size();
      // Room for as many as there are labels (j <= count_ - 1): fewer regrowths as the count changes.
      auto* transforms = staged_cut_transforms_.reserve(std::size_t(count_));
      for (std::size_t i = 0; i < j; ++i) transforms[i] = cuda_detail::deviceTransform(judged_at[i]);
      cut_transforms_.reserve(std::size_t(count_));
      MCFLOW_CUDA_CHECK(cudaMemcpyAsync(cut_transforms_.get(), transforms, j * sizeof(cuda_detail::DeviceTransform),
                                        cudaMemcpyHostToDevice, s));
      cut_costs_.reserve(plane() * std::size_t(count_ + 1));
      cut_outlier_only_.reserve(plane());
      cuda_detail::launchDataCosts(L, cut_transforms_.get(), int(j), use_occlusion ? occlusion_.get() : nullptr, config,
                                   cut_costs_.get(), cut_outlier_only_.get(), s);
    }
    reserveLabels(plane(), count_ + m);  // may move the labels to the other buffer
    cuda_detail::launchCutLabels(labels(), L.points1, count_, cuts_.get(), m,
                                 judged_at.empty() ? nullptr : cut_costs_.get(), scratch(), moved_.get(), s);
    MCFLOW_CUDA_WAIT(s);  // the staging buffer is reused next
  }

  // The twists and their transforms (packMotions) into motions_.
  void uploadMotions(const std::vector<Vector6d>& twists) {
    const std::size_t n = twists.size();
    // The staging buffer is rewritten only once the previous upload from it has finished (usually long ago: no
    // synchronisation of the whole stream after an upload).
    if (motions_uploaded_.recorded) MCFLOW_CUDA_CHECK(cudaEventSynchronize(motions_uploaded_.event));
    double* staged = staged_motions_.reserve(n * 18);
    packMotions(twists, staged);
    motions_.reserve(std::max<std::size_t>(n * 18, 1));
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(motions_.get(), staged, n * 18 * sizeof(double), cudaMemcpyHostToDevice, stream_.stream));
    MCFLOW_CUDA_CHECK(cudaEventRecord(motions_uploaded_.event, stream_.stream));
    motions_uploaded_.recorded = true;
  }

  void zeroDual(std::size_t p, int count) {
    dual_.reserve(p * std::size_t(count) * 2);
    MCFLOW_CUDA_CHECK(cudaMemsetAsync(dual_.get(), 0, p * std::size_t(count) * 2 * sizeof(float), stream_.stream));
  }
  void clearOcclusionAndDual() {
    const std::size_t p = plane();
    occlusion_.reserve(p);
    MCFLOW_CUDA_CHECK(cudaMemsetAsync(occlusion_.get(), 0, p, stream_.stream));
    zeroDual(p, count_);
  }

  template <typename T>
  void upload(DeviceBuffer<T>& buffer, const std::vector<T>& host, std::size_t count) {
    if (host.size() != count)
      throw InputError("CUDA backend: a pyramid image holds " + std::to_string(host.size()) + " values, expected " +
                       std::to_string(count));
    buffer.reserve(std::max<std::size_t>(count, 1));
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(buffer.get(), host.data(), count * sizeof(T), cudaMemcpyHostToDevice, stream_.stream));
  }

  // Up into hard_labels_ through the page-locked staging buffer (reused by the next small transfer: the caller waits).
  void uploadHardLabels(const ImageI32& hard) {
    const std::size_t p = hard.data.size();
    int* staged = staged_ints_.reserve(p);
    std::copy_n(hard.data.data(), p, staged);
    hard_labels_.reserve(p);
    MCFLOW_CUDA_CHECK(
        cudaMemcpyAsync(hard_labels_.get(), staged, p * sizeof(int), cudaMemcpyHostToDevice, stream_.stream));
  }

  // kmeans.cu's one-block K-means on level L's valid points (only where `uncovered_hard` is -1, whose labels it then
  // writes, when given), waited for: its answer.
  cuda_detail::KMeansOutcome runKMeans(const DeviceLevel& L, int k, int max_iterations, double tolerance_m,
                                       unsigned seed, int* uncovered_hard, int first_new) {
    const std::size_t p = std::size_t(L.width) * L.height;
    cuda_detail::KMeansRun run;
    const std::vector<double> draws = kmeansSeedingDraws(seed, k);
    std::copy(draws.begin(), draws.end(), run.draws);
    run.k = k;
    run.max_iterations = max_iterations;
    run.tolerance_m = tolerance_m;
    run.uncovered_hard = uncovered_hard;
    run.first_new = first_new;
    kmeans_points_.reserve(3 * p);
    kmeans_distances_.reserve(p);
    kmeans_assignment_.reserve(p);
    kmeans_outcome_.reserve(1);
    cuda_detail::launchKMeans(L.points1, run, kmeans_points_.get(), kmeans_distances_.get(), kmeans_assignment_.get(),
                              kmeans_outcome_.get(), stream_.stream);
    cuda_detail::KMeansOutcome outcome;
    download(&outcome, kmeans_outcome_.get(), 1, staged_kmeans_);
    return outcome;
  }

  // One-hot labels at `level` from hard_labels_ (motion_labels + 1 planes); clears the occlusion and the dual.
  void labelsFromHardLabels(int level, int motion_labels) {
    count_ = 0;  // nothing to keep when the buffers grow
    level_ = level;
    hard_level_ = level;
    reserveLabels(plane(), motion_labels + 1);
    count_ = motion_labels + 1;
    cuda_detail::launchOneHotLabels(levelAt(level).points1, hard_labels_.get(), count_, labels(), stream_.stream);
    carried_held_ = false;
    clearOcclusionAndDual();
  }

  template <typename T>
  void download(T* host, const T* device, std::size_t count, PinnedBuffer<T>& staging) {
    T* staged = staging.reserve(count);
    MCFLOW_CUDA_CHECK(cudaMemcpyAsync(staged, device, count * sizeof(T), cudaMemcpyDeviceToHost, stream_.stream));
    MCFLOW_CUDA_WAIT(stream_.stream);
    std::copy_n(staged, count, host);
  }

  int device_ = 0;  // CUDA device of the stream and every buffer below
  cuda_detail::StreamHolder stream_;
  // Page-locked staging of the small transfers (each is synchronised before its buffer is used again).
  PinnedBuffer<float> staged_floats_;
  PinnedBuffer<int> staged_ints_;
  PinnedBuffer<double> staged_doubles_;
  PinnedBuffer<cuda_detail::DeviceTransform> staged_transforms_;
  PinnedBuffer<cuda_detail::DeviceTransform> staged_cut_transforms_;  // the cuts by the data's twists
  PinnedBuffer<unsigned long long> staged_counts_;
  PinnedBuffer<std::uint8_t> staged_bytes_;
  PinnedBuffer<double> staged_motions_;
  PinnedBuffer<cuda_detail::KMeansOutcome> staged_kmeans_;
  static constexpr int kOutputImages = 6;                     // StagedOutputs' images
  cuda_detail::EventHolder image_downloaded_[kOutputImages];  // each output image has reached its staging buffer
  cuda_detail::EventHolder motions_uploaded_;                 // the last upload from staged_motions_ has finished
  PinnedBuffer<float> staged_frames_;
  Intrinsics K_;
  std::vector<int> valid_counts_;
  DeviceBuffer<int> valid_counts_device_;
  std::vector<ImageF> host_points_;  // frame 1's points per level, downloaded at the first request in a pair
  std::vector<bool> host_points_current_;
  std::vector<std::unique_ptr<LevelBuffers>> buffers_;
  std::vector<DeviceLevel> levels_;
  DeviceBuffer<float> label_buffers_[2], level_labels_[2], before_, data_cost_, weight_x_, weight_y_, warped_z_;
  DeviceBuffer<float> scene_flow_, optical_flow_, moved_depth_;
  DeviceBuffer<int> ids_;
  // Which Result::device_outputs the images above hold (0: none; serials are unique across the process's backends).
  std::uint64_t outputs_serial_ = 0;
  int outputs_width_ = 0, outputs_height_ = 0, outputs_motion_labels_ = -1;
  // Where that result's host images live (moves keep them, copies do not).
  const void* outputs_labels_memory_ = nullptr;
  const void* outputs_flow_memory_ = nullptr;
  const void* outputs_moved_depth_memory_ = nullptr;
  DeviceBuffer<std::uint8_t> occlusion_, level_occlusion_, outlier_only_;
  DeviceBuffer<float> dual_;
  DeviceBuffer<double> scalar_, partials_, motions_, cuts_;  // partials_: chunked sums' scratch
  DeviceBuffer<cuda_detail::DeviceTransform> transforms_;
  DeviceBuffer<cuda_detail::DeviceTransform> cut_transforms_;
  DeviceBuffer<float> cut_costs_;  // data costs of the cuts by the data, one plane each (+ outlier)
  DeviceBuffer<std::uint8_t> cut_outlier_only_;
  DeviceBuffer<int> counts_, hard_labels_;
  // kmeansCentres: the level's valid points, the seeding's distances, the clusters, the answer.
  DeviceBuffer<float> kmeans_points_;
  DeviceBuffer<double> kmeans_distances_;
  DeviceBuffer<int> kmeans_assignment_;
  DeviceBuffer<cuda_detail::KMeansOutcome> kmeans_outcome_;
  // holdCarriedLabels: the carried label each pixel started in (-1: none), at level_; two buffers for moveLabels.
  DeviceBuffer<int> carried_[2];
  int carried_slot_ = 0;
  bool carried_held_ = false;
  int hard_level_ = -1;  // the level of hard_labels_
  int* carried() { return carried_[carried_slot_].get(); }
  // carrySegments: the previous pair's ids (and dormant regions), flow and moved depth; the splat's scratch; the
  // carried ids (and dormant regions) and the label level's majority ids, downloaded together.
  DeviceBuffer<unsigned char> carry_in_;
  DeviceBuffer<int> carry_kept_, carry_out_;
  DeviceBuffer<unsigned long long> carry_winner_;
  PinnedBuffer<unsigned char> staged_carry_in_;
  PinnedBuffer<int> staged_carry_out_;
  DeviceBuffer<long long> targets_;
  DeviceBuffer<unsigned long long> moved_;
  int current_ = 0, count_ = 0, level_ = 0, weights_level_ = -1;
  // Declared last: destroyed first, before the stream and the buffers they work on.
  std::unique_ptr<cuda_detail::DeviceMotionAccumulator> accumulator_;
  std::unique_ptr<cuda_detail::DevicePrimalDual> primal_dual_;
};

}  // namespace

CudaCounters cudaCounters() {
  CudaCounters c;
  c.kernel_launches = cuda_detail::kernel_launches.load();
  c.device_allocations = cuda_detail::device_allocations.load();
  c.pinned_allocations = cuda_detail::pinned_allocations.load();
  c.host_waits = cuda_detail::host_waits.load();
  c.carry_bytes_uploaded = cuda_detail::carry_bytes_uploaded.load();
  c.graph_instantiations = cuda_detail::graph_instantiations.load();
  return c;
}

bool cudaDeviceMemory(std::size_t* used, std::size_t* total) {
  std::size_t free_bytes = 0, total_bytes = 0;
  if (!cudaBackendAvailable(nullptr) || cudaMemGetInfo(&free_bytes, &total_bytes) != cudaSuccess) {
    cudaGetLastError();
    return false;
  }
  if (used) *used = total_bytes - free_bytes;
  if (total) *total = total_bytes;
  return true;
}

std::unique_ptr<SolveBackend> makeCudaSolveBackend(int cuda_device) {
  std::string why;
  if (!cudaBackendAvailable(&why, cuda_device)) throw BackendError("CUDA backend requested but unavailable: " + why);
  MCFLOW_CUDA_CHECK(cudaSetDevice(cuda_device));  // the backend's stream and buffers are created on it
  return std::make_unique<CudaSolveBackend>(cuda_device);
}

}  // namespace mc_flow
