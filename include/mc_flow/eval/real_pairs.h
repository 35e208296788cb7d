/**
 * @file real_pairs.h
 * @brief The paper's Table 1 on the real RGB-D pairs: residual RMSE after warping frame 2 back, for zero flow,
 * one rigid motion (Config::initial_labels = 1: dense robust visual odometry) and MC-Flow with both
 * regularisers, all scored on one common pixel set; plus solve times per stage.
 *
 * One code path for every tool that benchmarks real pairs: `mcflow bench-real` (the PNG pairs, decoded by
 * io::loadRealPair) and `mcflow_bench --real` (the PFM folders of `mcflow export-real`, on machines without OpenCV)
 * prepare, solve and score a pair with these functions. No OpenCV here.
 */
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/metrics.h"

namespace mc_flow {

/// @brief One real pair ready for the solver.
struct RealPair {
  std::string name;
  RgbdFrame frame1, frame2;  ///< depth cleaned to [min_depth, max_depth] (0 elsewhere)
  Intrinsics intrinsics;     ///< at the frames' resolution [px]
};

/// @brief The folders of the shared real-pair set, in table order.
std::vector<std::string> realPairNames();

/// @brief Intrinsics at 640x480 of a pair of the shared set (from its README); throws InputError naming an
/// unknown pair.
Intrinsics realPairIntrinsics640(const std::string& name);

/// @brief Sets depth outside [min_depth, max_depth] or non-finite to 0 (what the solver's pyramid does), so the
/// metrics see the same valid pixels as the solver.
ImageF cleanDepth(const ImageF& depth, const Config& config);

/// @brief Halves a frame as the solver's pyramid does: [1 3 3 1] intensity filter and the depth-aware
/// mc_flow::downsampleDepth (no averaging across discontinuities, range Config::depth_downsample_range).
/// The depth is cleaned first. Pair it with Intrinsics::scaled(0.5).
RgbdFrame halveFrame(const RgbdFrame& frame, const Config& config);

/// @brief The pair as the solver and the table see it from frames decoded at 640x480 (`source` names frame 1's
/// file in errors): depth cleaned (cleanDepth), then halved `halvings` times (1 = 320x240, the paper's resolution)
/// with the intrinsics of the shared set. Throws InputError for another size or frames of different sizes.
RealPair prepareRealPair(const std::string& name, RgbdFrame frame1, RgbdFrame frame2, const std::string& source,
                         int halvings, const Config& config);

/// @brief Writes a prepared pair as `mcflow export-real` does, for machines without OpenCV (the GPU machine):
/// `dir`/{intensity0,depth0,intensity1,depth1}.pfm (float: intensity in [0, 1], depth in metres) and intrinsics.txt
/// ("fx fy cx cy", 17 digits), so that readRealPairFolder gives back the same pair bit for bit.
void writeRealPairFolder(const std::string& dir, const RealPair& pair);

/// @brief Reads a folder written by writeRealPairFolder. The pair's name is the folder's without the "_WxH" that
/// `mcflow export-real` appends. Throws InputError naming a missing or malformed file.
RealPair readRealPairFolder(const std::string& dir);

/// @brief How the pixels excluded from every method's residual are chosen.
enum class ExclusionMask {
  UnionOfAll,  ///< occlusions estimated by any of the solves (one label, MC-TV, MC-Quad)
  McFlowOnly,  ///< occlusions estimated by the MC-Flow solves (TV, Quad) only
};

/// @brief 255 where a pixel is excluded: any of `occlusions` set, or the warp of any of `scene_flows` (null =
/// zero flow) cannot be scored there (invalid frame-1 depth, non-finite flow, projection outside frame 2 or onto
/// invalid depth: the cases mc_flow::warpResidualRmse skips). With this mask every flow is scored on the same
/// pixels.
ImageU8 commonExclusionMask(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K,
                            const std::vector<const ImageF*>& scene_flows,
                            const std::vector<const ImageU8*>& occlusions);

/// @brief One row of the table.
struct MethodScore {
  std::string method;       ///< "zero flow", "one label", "MC-TV", "MC-Quad"
  ResidualRmse rmse;        ///< on the pair's common pixel set
  bool solved = false;      ///< false for zero flow (no segments, no timings)
  int segments = 0;         ///< motion segments of the result
  std::string label_trace;  ///< labelCountTrace(result, true): the count over the outer iterations
  StageTimings timings;     ///< median over the repetitions [ms], per stage
};

/// @brief The four rows of one pair.
struct PairScores {
  std::string pair;
  int width = 0, height = 0;
  std::size_t pixels = 0;  ///< pixels scored (the same for every row)
  std::vector<MethodScore> methods;
  const MethodScore& method(const std::string& name) const;  ///< throws InputError on an unknown name
};

/// @brief The solves of one pair: one label, MC-TV and MC-Quad (from `base`, with only initial_labels /
/// regularizer changed), each run `repeat` times (timings = median; results of the last run).
struct PairSolves {
  Result one_label, tv, quad;
  StageTimings one_label_time, tv_time, quad_time;
};
PairSolves solveRealPair(const RealPair& pair, const Config& base, int repeat);

/// @brief Scores zero flow and the three solves on the common pixel set chosen by `mask`.
PairScores scoreRealPair(const RealPair& pair, const PairSolves& solves, ExclusionMask mask);

/// @brief Per-pair table (photometric RMSE, geometric RMSE [mm], segments, time per stage [ms]), the average over
/// pairs of each method, then each MC-Flow solve's motion labels over the outer iterations.
std::string realBenchTable(const std::vector<PairScores>& scores);

/// @brief Table 1 over `names`: each pair loaded by `load` (io::loadRealPair, readRealPairFolder), solved `repeat`
/// times per method (solveRealPair) and scored (scoreRealPair); `progress` (may be empty) hears of each pair first.
/// `backend` (may be null) receives the backend the solves ran on.
std::vector<PairScores> benchRealPairs(const std::vector<std::string>& names,
                                       const std::function<RealPair(const std::string&)>& load, const Config& config,
                                       int repeat, ExclusionMask mask,
                                       const std::function<void(const std::string&)>& progress, std::string* backend);

}  // namespace mc_flow
