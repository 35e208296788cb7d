/**
 * @file config.h
 * @brief Every solver parameter, with its unit and default, in one place.
 *
 * The CLI flags, the JSON config file and the ROS dynamic_reconfigure parameters all map onto this
 * struct; none of them repeats a default. `validate()` throws mc_flow::ConfigError naming the field.
 */
#pragma once

#include <string>
#include <vector>

namespace mc_flow {

enum class Regularizer { Quadratic, TotalVariation };
enum class Backend { Auto, Cpu, Cuda };

std::string toString(Regularizer r);
std::string toString(Backend b);
/// @brief Parses "quad"/"quadratic"/"tv"; throws ConfigError naming the text otherwise.
Regularizer parseRegularizer(const std::string& s);
/// @brief Parses "auto"/"cpu"/"cuda"; throws ConfigError naming the text otherwise.
Backend parseBackend(const std::string& s);

struct Config {
  // ---- input ----
  double max_depth = 5.0;   ///< [m] depth beyond this is treated as invalid (paper: 5 m)
  double min_depth = 0.1;   ///< [m] depth below this is treated as invalid

  // ---- pyramid ----
  int coarsest_min_width = 20;  ///< [px] the pyramid stops before a level narrower than this (20x15 at 320x240 input)
  int processing_level = 0;     ///< pyramid level the solver finishes at (0 = input resolution; 1 = half);
                                ///< outputs are always written at the input resolution
  double depth_downsample_range = 0.1;  ///< [m] neighbours further than this from the centre depth are not averaged

  // ---- initialisation ----
  int initial_labels = 20;       ///< K-means clusters on 3D points (paper: 20)
  int kmeans_max_iterations = 10;
  double kmeans_tolerance = 0.01;  ///< [m] stop when no centre moves further
  int kmeans_level_offset = 2;     ///< K-means runs this many levels coarser than the label level
  unsigned seed = 1;               ///< K-means seeding is deterministic for a given seed
  bool dominant_motion_init = true;  ///< start every label from the motion of the whole scene (one label),
                                     ///< estimated down to the label level, instead of from zero

  // ---- outer loop (Algorithm 1) ----
  int outer_iterations = 3;           ///< motion step + label step + label-count update, repeated
  double outer_convergence = 1e-3;    ///< stop when the mean absolute label change is below this
  int label_level_offset = 1;         ///< label step inside the loop runs this many levels above processing_level
                                      ///< (a final label step at processing_level follows the loop)

  // ---- motion step (Cauchy IRLS, eqs. 8-10, interpolation model eq. 2) ----
  int motion_iterations_per_level = 6;  ///< IRLS iterations at each pyramid level (first outer iteration)
  int motion_iterations_refine = 3;     ///< IRLS iterations per level in later outer iterations (warm start)
  int motion_coarse_levels_after_first = 0;  ///< later outer iterations start this many levels above the finest:
                                             ///< warm-started twists need no coarse levels, and coarse levels blur
                                             ///< small parts into their surroundings (biased motions)
  double alpha = 2.0;             ///< weight of the geometric (depth) cost against the photometric one
  double cauchy_c_intensity = 0.04;  ///< [intensity, 0..1] Cauchy scale of photometric residuals
  double cauchy_c_depth = 0.03;      ///< [m] Cauchy scale of geometric residuals
  double motion_damping = 1e-4;      ///< Levenberg damping added to the normal equations (relative to the diagonal)
  double motion_min_update = 1e-6;   ///< stop IRLS at a level when the largest twist update is below this
  double min_label_weight = 0.01;    ///< soft-label values below this do not enter a label's normal equations
  double motion_min_label_pixels = 64;  ///< a label with fewer (weighted) pixels at a pyramid level keeps its
                                        ///< twist there: small parts are blurred into their surroundings at
                                        ///< coarse levels and give biased motions

  // ---- label step (eq. 4, primal-dual, supplement) ----
  Regularizer regularizer = Regularizer::Quadratic;
  double lambda_quadratic = 4.0;   ///< weight of the quadratic regulariser (eq. 13)
  double lambda_tv = 1.0;          ///< weight of the TV regulariser (eq. 12)
  int label_iterations = 50;       ///< primal-dual iterations per label step (warm-started across outer iterations)
  int label_iterations_final = 30; ///< primal-dual iterations of the final, full-resolution label step
  double label_tolerance = 1e-4;   ///< stop when the largest label change of an iteration is below this
  double outlier_cost = 3.5;       ///< K_D: constant data cost of the outlier label (normalised Cauchy units)
  double out_of_view_cost = 5.0;   ///< data cost of a label whose warp leaves the image at a non-occluded pixel
  double min_geometric_weight = 1e-3;  ///< floor of the 3D-distance weights (0 would disconnect the graph)

  // ---- label count (section 5) ----
  double label_cost = 0.001;         ///< [normalised Cauchy cost per valid label-level pixel] price of one motion:
                                     ///< labels merge when sharing a motion costs less data cost than this times
                                     ///< the valid pixels, and split when a second motion saves more
  int max_splits_per_iteration = 2;  ///< new labels proposed by splitting, per outer iteration (0 = never split)
  int max_labels = 64;               ///< [labels] splits stop at this many motion labels
  double min_support_fraction = 0.004;  ///< labels with support below this fraction of the valid pixels go to the outlier label

  // ---- occlusion (section 6) ----
  bool detect_occlusions = true;
  double occlusion_kz = 20.0;   ///< [1/m] K_z: weight of the depth test against the warp count
  double occlusion_ko = 2.5;    ///< K_o: threshold on C(W(x)) + K_z * O_Z(x)

  // ---- stream: warm start from the previous pair (Solver::solve with a previous result) ----
  bool warm_start = true;              ///< a previous pair's result seeds the labels and motions (false: every pair
                                       ///< starts from K-means; the previous result then only keeps the segment ids)
  int warm_outer_iterations = 2;       ///< outer iterations of a warm-started solve
  int warm_motion_coarse_levels = 2;   ///< the first motion step of a warm solve starts this many levels above the finest
  double warm_depth_tolerance = 0.05;  ///< [m] a carried label is kept where the depth it predicts is this close to the
                                       ///< observed depth; elsewhere the pixel is uncovered
  double warm_min_coverage = 0.5;      ///< [fraction of valid frame-1 pixels] fewer covered by carried labels: cold start
  double warm_max_energy_ratio = 1.5;  ///< a warm result whose energy per valid pixel exceeds this times the previous
                                       ///< pair's is solved again from K-means, and the lower energy is kept
  double id_min_overlap = 0.3;         ///< [fraction] a cold-started segment keeps a previous id when it shares at least
                                       ///< this fraction of the smaller region with that id's carried pixels

  // ---- execution ----
  Backend backend = Backend::Auto;  ///< label step on the GPU when available (Auto) or forced
  int threads = 0;                  ///< OpenMP threads (0 = OpenMP default)
  bool verbose = false;             ///< progress on stderr

  /// @brief Throws ConfigError naming the first field out of range.
  void validate() const;
  /// @brief The regulariser weight for the selected regulariser.
  double lambda() const { return regularizer == Regularizer::Quadratic ? lambda_quadratic : lambda_tv; }
  /// @brief Sets a field by name from text (JSON/YAML keys and CLI use this); throws ConfigError on an
  /// unknown name or an unparsable value.
  void set(const std::string& name, const std::string& value);
  /// @brief Every field as (name, value-as-text), in declaration order.
  std::vector<std::pair<std::string, std::string>> fields() const;
};

}  // namespace mc_flow
