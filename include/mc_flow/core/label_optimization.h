/**
 * @file label_optimization.h
 * @brief Label step: the convex relaxed model (eq. 4) over the simplex, solved by the diagonally
 * preconditioned primal-dual algorithm (Pock & Chambolle 2011), TV or quadratic regulariser on the
 * 3D-distance-weighted gradient (eq. 11). Derivation: docs/ALGORITHM.md.
 */
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "mc_flow/core/config.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/se3.h"
#include "mc_flow/core/soft_labels.h"

namespace mc_flow {

/// @brief Everything the primal-dual iteration needs, at one resolution.
struct LabelProblem {
  int width = 0, height = 0, count = 0;  ///< count includes the outlier label (last)
  std::vector<float> data_cost;          ///< count planes, D_i(x); the outlier plane is K_D
  ImageF weight_x;                       ///< r_1(x): weight of u(x+1,y) - u(x,y); 0 at the last column
  ImageF weight_y;                       ///< r_2(x): weight of u(x,y+1) - u(x,y); 0 at the last row
  ImageU8 outlier_only;                  ///< 1 where only the outlier label is feasible (no depth)
  Regularizer regularizer = Regularizer::Quadratic;
  double lambda = 1.0;
};

/// @brief Dual variable p: two planes (x, y components) per label.
struct LabelDual {
  int width = 0, height = 0, count = 0;
  std::vector<float> p;  ///< plane 2*i = p_x of label i, 2*i+1 = p_y
  void reset(int w, int h, int n) {
    width = w;
    height = h;
    count = n;
    p.assign(std::size_t(w) * h * n * 2, 0.f);
  }
};

struct LabelStats {
  int iterations = 0;
  double last_change = 0;  ///< largest |u_new - u_old| of the last iteration
  double energy = 0;       ///< E(u) of eq. 4 at the end
};

/// @brief Euclidean projection of v[0..n) onto the probability simplex (Michelot's active-set algorithm, see
/// simplex_projection.h; the same result as the sort-based projection of Duchi et al. 2008).
void projectOntoSimplex(float* v, int n);

/// @brief Geometric weights r = footprint / max(footprint, |P(x) - P(neighbour)|), footprint = mean depth / f:
/// about 1 between neighbours on a smooth fronto-parallel surface, small across depth discontinuities,
/// `min_weight` where either point is invalid (keeps the graph connected).
void geometricWeights(const PyramidLevel& frame1, double min_weight, ImageF& weight_x, ImageF& weight_y);

/// @brief D_i(x) of eq. 5 for every motion label (each rigid motion alone), K_D for the outlier label,
/// 0 at occluded pixels (section 6), `out_of_view_cost` where a warp leaves the image.
/// Also sets `outlier_only` where frame 1 has no depth.
void computeDataCosts(const PyramidLevel& frame1, const PyramidLevel& frame2, const std::vector<Vector6d>& twists,
                      const ImageU8* occluded, const Config& config, LabelProblem& problem);

/// @brief Stream mode's switching cost (Config::warm_switch_cost): where `carried` holds a label (>= 0, the segment
/// of the previous pair the pixel was carried in), every other label's cost, the outlier's included, rises by
/// `cost`; pixels without depth are left alone. `carried` has the problem's size.
void addSwitchingCost(const ImageI32& carried, float cost, LabelProblem& problem);

/// @brief The part of E(u) that addSwitchingCost put in: cost x the sum over pixels with a carried label (and depth)
/// of 1 - u_carried(x), summed in double. The label step reports E(u) without it.
double switchingEnergy(const ImageI32& carried, float cost, const LabelProblem& problem, const SoftLabels& u);

/// @brief E(u) = sum_i <u_i, D_i> + R(u).
double labelEnergy(const LabelProblem& problem, const SoftLabels& u);

/// @brief Primal-dual solver; CPU and CUDA implementations behind one interface.
class LabelOptimizer {
 public:
  virtual ~LabelOptimizer() = default;
  /// @brief Runs up to `iterations` primal-dual iterations from the warm start (u, p); u stays on the simplex.
  virtual LabelStats optimize(const LabelProblem& problem, SoftLabels& u, LabelDual& p, int iterations,
                              double tolerance) = 0;
  virtual std::string name() const = 0;
};

/// @brief The CPU implementation (OpenMP).
std::unique_ptr<LabelOptimizer> makeCpuLabelOptimizer();
/// @brief The CUDA implementation (host-memory problems: tests and mcflow_bench_labels; the CUDA SolveBackend runs
/// the same engine on its device buffers); throws BackendError when unavailable (cudaBackendAvailable,
/// solve_backend.h).
std::unique_ptr<LabelOptimizer> makeCudaLabelOptimizer();

}  // namespace mc_flow
