/**
 * @file mcflow.cpp
 * @brief The `mcflow` command-line tool: run the solver on files, render synthetic pairs, evaluate, demo.
 *
 * Exit codes: 0 success; 1 bad input, configuration or file error; 2 usage error or unusable backend;
 * 3 unexpected internal error.
 */
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/testing/synthetic_scene.h"
#include "mc_flow/io/benchmark.h"
#include "mc_flow/io/camera_info.h"
#include "mc_flow/io/config_file.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/resources.h"
#include "mc_flow/io/result_io.h"

namespace {

using namespace mc_flow;

/// A command line that does not follow the usage: print the usage and exit 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Option {
  std::string name;  // without the leading "--"
  bool takes_value;
  std::string help;
};

struct Command {
  std::string name, synopsis, description;
  std::vector<Option> options;
};

const std::vector<Option> kInputOptions = {
    {"rgb1", true, "colour image of frame 1 (8-bit RGB/grey PNG/JPG/PPM/PGM, or 16-bit grey)"},
    {"depth1", true, "depth of frame 1: 16-bit PNG/PGM (see --depth-scale) or float PFM/EXR/TIFF in metres"},
    {"rgb2", true, "colour image of frame 2"},
    {"depth2", true, "depth of frame 2"},
    {"intrinsics", true, "FX,FY,CX,CY in pixels (e.g. 525,525,319.5,239.5)"},
    {"camera-info", true, "ROS camera_info YAML file (K, or P) instead of --intrinsics"},
    {"depth-scale", true, "16-bit depth units per metre (default 1000 = mm as ROS 16UC1; TUM data: 5000)"},
};

std::vector<Command> commands() {
  std::vector<Command> list;
  Command run{"run",
              "mcflow run --rgb1 F --depth1 F --rgb2 F --depth2 F (--intrinsics FX,FY,CX,CY | --camera-info F) --out DIR",
              "Estimates piece-wise rigid scene flow between two RGB-D frames and writes optical_flow.flo, "
              "scene_flow.pfm, labels.png, soft_labels.npy, occlusion.png, segments.json, report.json, "
              "segmentation.png, flow.png and overview.png into DIR.",
              kInputOptions};
  for (const Option& o : std::vector<Option>{
           {"max-depth", true, "[m] depth beyond this is invalid (Config::max_depth)"},
           {"regularizer", true, "quad | tv"},
           {"labels", true, "initial number of labels (K-means clusters, Config::initial_labels)"},
           {"backend", true, "auto | cpu | cuda"},
           {"config", true, "JSON or YAML file of Config fields (keys = Config member names)"},
           {"set", true, "name=value: sets one Config field; may be repeated; overrides --config and flags"},
           {"processing-level", true, "pyramid level the solver finishes at (0 = input resolution)"},
           {"out", true, "output directory (created)"},
           {"verbose", false, "progress of the solver on stderr"},
           {"help", false, "this help"}})
    run.options.push_back(o);
  list.push_back(run);

  list.push_back({"synth",
                  "mcflow synth --out DIR [--variant K] [--width W --height H] [--noise] [--seed S]",
                  "Renders a synthetic RGB-D pair with ground truth: rgb1/2.png, depth1/2.png (16-bit mm), "
                  "depth1/2.pfm (float metres), intrinsics.txt, camera_info.yaml, gt_optical_flow.flo, "
                  "gt_scene_flow.pfm, gt_occlusion.png, gt_parts.png, gt_segments.json.",
                  {{"out", true, "output directory (created)"},
                   {"variant", true, "scene variant 0..N-1"},
                   {"width", true, "image width in pixels (default 320)"},
                   {"height", true, "image height in pixels (default 240)"},
                   {"noise", false, "add Kinect-like intensity and depth noise"},
                   {"seed", true, "noise seed"},
                   {"help", false, "this help"}}});

  Command eval{"eval", "mcflow eval --result DIR [--gt DIR] [input options]",
               "Evaluates a result: optical-flow EPE/AAE on non-occluded pixels, 3D EPE, segmentation and "
               "occlusion agreement (with --gt), and the RMSE of photometric and geometric residuals after "
               "warping frame 2 back (with the inputs; estimated occlusions excluded). With --gt pointing at "
               "a `mcflow synth` directory the inputs default to its files. Prints a table and writes "
               "DIR/eval.json.",
               {{"result", true, "directory written by `mcflow run`"}, {"gt", true, "directory written by `mcflow synth`"}}};
  for (const Option& o : kInputOptions) eval.options.push_back(o);
  eval.options.push_back({"help", false, "this help"});
  list.push_back(eval);

  list.push_back({"demo", "mcflow demo --out DIR",
                  "Renders the synthetic pair (variant 0), runs the solver on it, writes the inputs, the ground "
                  "truth, every output and eval.json into DIR, and prints a summary.",
                  {{"out", true, "output directory (created)"},
                   {"backend", true, "auto | cpu | cuda"},
                   {"width", true, "image width (default 320)"},
                   {"height", true, "image height (default 240)"},
                   {"verbose", false, "progress of the solver on stderr"},
                   {"help", false, "this help"}}});

  list.push_back({"bench-real",
                  "mcflow bench-real --data DIR [--pairs A,B] [--set name=value ...] [--processing-level L] [--repeat N]",
                  "Table 1 of the paper on the real RGB-D pairs in DIR (folders with color0/1.png and 16-bit "
                  "depth0/1.png, 5000 units per metre): for zero flow, one rigid motion (initial_labels = 1, dense "
                  "robust visual odometry), MC-TV and MC-Quad, the RMSE of the photometric (intensity 0..1) and "
                  "geometric (mm) residuals after warping frame 2 back, all on one pixel set (valid, not occluded "
                  "in any solve, every warp inside frame 2), the number of segments and the median time per stage "
                  "[ms]; then the average over pairs. Inputs are halved to 320x240 (the paper's resolution) with "
                  "the solver's depth-aware downsampling unless --full-resolution is given.",
                  {{"data", true, "directory of the real pairs (e.g. $MCFLOW_SHARED_DATA/real_pairs)"},
                   {"pairs", true, "comma-separated folder names (default: the four pairs of the shared set)"},
                   {"config", true, "JSON or YAML file of Config fields"},
                   {"set", true, "name=value: sets one Config field; may be repeated"},
                   {"processing-level", true, "pyramid level the solver finishes at (Config::processing_level)"},
                   {"backend", true, "auto | cpu | cuda"},
                   {"full-resolution", false, "keep the 640x480 input (default: halve to 320x240)"},
                   {"mask", true, "union (default: occlusions of all three solves excluded) | mcflow (MC-Flow's only)"},
                   {"repeat", true, "solves per method and pair; times are the median (default 1)"},
                   {"verbose", false, "progress of the solver on stderr"},
                   {"help", false, "this help"}}});
  return list;
}

void printMainUsage(std::ostream& out) {
  out << "mcflow - piece-wise rigid scene flow from RGB-D pairs (MC-Flow, Jaimez et al. CVPR 2016)\n\n"
         "usage: mcflow <command> [options]     (mcflow <command> --help for its options)\n\ncommands:\n";
  for (const Command& c : commands()) out << "  " << c.synopsis << "\n";
  out << "\nexit codes: 0 success, 1 bad input/config/file, 2 usage error or unusable backend, 3 internal error\n";
}

void printCommandUsage(const Command& c, std::ostream& out) {
  out << "usage: " << c.synopsis << "\n\n" << c.description << "\n\noptions:\n";
  for (const Option& o : c.options) {
    std::string left = "--" + o.name + (o.takes_value ? " VALUE" : "");
    out << "  " << left << std::string(left.size() < 24 ? 24 - left.size() : 1, ' ') << o.help << "\n";
  }
}

struct Arguments {
  std::map<std::string, std::string> values;
  std::vector<std::string> assignments;  // --set, in order
  std::set<std::string> flags;
  bool has(const std::string& name) const { return values.count(name) || flags.count(name); }
  std::string get(const std::string& name) const {
    auto it = values.find(name);
    return it == values.end() ? std::string() : it->second;
  }
  std::string require(const std::string& name) const {
    if (!values.count(name)) throw UsageError("missing required option --" + name);
    return values.at(name);
  }
};

Arguments parseArguments(const Command& command, int argc, char** argv, int first) {
  Arguments args;
  for (int i = first; i < argc; ++i) {
    std::string token = argv[i];
    if (token.rfind("--", 0) != 0) throw UsageError("unexpected argument '" + token + "'");
    std::string name = token.substr(2), value;
    bool inline_value = false;
    const std::size_t eq = name.find('=');
    if (eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
      inline_value = true;
    }
    const Option* option = nullptr;
    for (const Option& o : command.options)
      if (o.name == name) option = &o;
    if (!option) throw UsageError("unknown option '--" + name + "' for `mcflow " + command.name + "`");
    if (!option->takes_value) {
      if (inline_value) throw UsageError("option --" + name + " takes no value");
      args.flags.insert(name);
      continue;
    }
    if (!inline_value) {
      if (i + 1 >= argc) throw UsageError("option --" + name + " needs a value");
      value = argv[++i];
    }
    if (name == "set") args.assignments.push_back(value);
    else if (args.values.count(name)) throw UsageError("option --" + name + " given twice");
    else args.values[name] = value;
  }
  return args;
}

double parseNumber(const std::string& flag, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || !end || *end != '\0' || !std::isfinite(v))
    throw InputError("--" + flag + " '" + text + "': expected a number");
  return v;
}

int parseInteger(const std::string& flag, const std::string& text) {
  const double v = parseNumber(flag, text);
  if (v != std::floor(v) || std::fabs(v) > 1e9) throw InputError("--" + flag + " '" + text + "': expected an integer");
  return int(v);
}

double elapsedMs(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

void progress(const std::string& message) { std::cerr << "mcflow: " << message << std::endl; }

io::PairPaths inputPaths(const Arguments& args) {
  io::PairPaths paths;
  paths.rgb1 = args.require("rgb1");
  paths.depth1 = args.require("depth1");
  paths.rgb2 = args.require("rgb2");
  paths.depth2 = args.require("depth2");
  if (args.has("depth-scale")) {
    paths.depth_scale = parseNumber("depth-scale", args.get("depth-scale"));
    if (!(paths.depth_scale > 0)) throw InputError("--depth-scale '" + args.get("depth-scale") + "': must be > 0");
  }
  return paths;
}

Intrinsics inputIntrinsics(const Arguments& args, int width, int height) {
  if (args.has("intrinsics") && args.has("camera-info"))
    throw UsageError("give either --intrinsics or --camera-info, not both");
  if (args.has("intrinsics")) return io::parseIntrinsics(args.get("intrinsics"));
  if (!args.has("camera-info")) throw UsageError("missing --intrinsics FX,FY,CX,CY or --camera-info FILE");
  const io::CameraInfo info = io::loadCameraInfo(args.get("camera-info"));
  if (width > 0 && info.width > 0 && (info.width != width || info.height != height))
    std::cerr << "mcflow: warning: camera info '" << args.get("camera-info") << "' is for " << info.width << "x"
              << info.height << " but the images are " << width << "x" << height << "\n";
  return info.intrinsics;
}

/// Config from --config, then the dedicated flags, then --set, then --verbose; validated.
Config buildConfig(const Arguments& args) {
  Config config;
  if (args.has("config")) io::applyConfigFile(args.get("config"), config);
  if (args.has("max-depth")) config.max_depth = parseNumber("max-depth", args.get("max-depth"));
  if (args.has("labels")) config.initial_labels = parseInteger("labels", args.get("labels"));
  if (args.has("processing-level")) config.processing_level = parseInteger("processing-level", args.get("processing-level"));
  try {
    if (args.has("regularizer")) config.regularizer = parseRegularizer(args.get("regularizer"));
  } catch (const ConfigError& e) {
    throw ConfigError("--regularizer '" + args.get("regularizer") + "': " + e.what());
  }
  try {
    if (args.has("backend")) config.backend = parseBackend(args.get("backend"));
  } catch (const ConfigError& e) {
    throw ConfigError("--backend '" + args.get("backend") + "': " + e.what());
  }
  for (const std::string& a : args.assignments) io::applyConfigAssignment(a, config);
  if (args.has("verbose")) config.verbose = true;
  try {
    config.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(std::string("invalid configuration: ") + e.what());
  }
  return config;
}

/// Loads, solves and writes one pair; returns the result.
Result solveAndWrite(const io::PairPaths& paths, const Arguments& args, const Config& config, const std::string& out,
                     io::LoadedPair* loaded, Intrinsics* used_K) {
  io::createOutputDirectory(out);  // fail on an unwritable directory before the solve
  Solver solver(config);           // fails fast on an unusable backend

  // Read before loading: the estimate includes the loaded images. MCFLOW_MEMINFO (a file in /proc/meminfo's
  // format) stands in for /proc/meminfo in the tests.
  const char* meminfo = std::getenv("MCFLOW_MEMINFO");
  const std::uint64_t available =
      meminfo ? io::parseMemAvailable(io::readTextFile(meminfo)) : io::availableMemoryBytes();
  progress("loading " + paths.rgb1 + ", " + paths.depth1 + ", " + paths.rgb2 + ", " + paths.depth2 + "...");
  const auto load_start = std::chrono::steady_clock::now();
  io::LoadedPair pair = io::loadPair(paths);
  const io::SizeCheck size = io::checkRunSize(pair.frame1.width(), pair.frame1.height(), config,
                                              solver.backendName() == "cpu", available);
  if (!size.error.empty()) throw InputError(size.error);
  if (!size.warning.empty()) std::cerr << "mcflow: warning: " << size.warning << std::endl;
  const Intrinsics K = inputIntrinsics(args, pair.frame1.width(), pair.frame1.height());
  io::RunInfo info{paths.rgb1, paths.depth1, paths.rgb2, paths.depth2, paths.depth_scale, elapsedMs(load_start), 0};

  progress("solving (" + solver.backendName() + " backend, " + std::to_string(pair.frame1.width()) + "x" +
           std::to_string(pair.frame1.height()) + ", processing level " + std::to_string(config.processing_level) +
           ")...");
  Result result = solver.solve(pair.frame1, pair.frame2, K);
  progress("writing " + out + "...");
  io::writeResultDirectory(out, result, config, pair, info);
  if (loaded) *loaded = std::move(pair);
  if (used_K) *used_K = K;
  return result;
}

void printSegments(const Result& result) {
  std::printf("%zu segment(s) (motion over the frame interval):\n", result.segments.size());
  for (const Segment& s : result.segments)
    std::printf("  segment %2d: |v| = %7.1f mm, |w| = %6.2f deg, support %8.0f px, centroid (%.2f, %.2f, %.2f) m\n",
                s.id, 1000.0 * s.twist.head<3>().norm(), s.twist.tail<3>().norm() * 180.0 / M_PI, s.support,
                s.centroid.x(), s.centroid.y(), s.centroid.z());
}

void printTimings(const Result& result) {
  const StageTimings& t = result.timings;
  std::printf("timings [ms]: init %.1f, motion %.1f, labels %.1f, adaptation %.1f, occlusion %.1f, total %.1f (%s)\n",
              t.initialisation, t.motion, t.labels, t.adaptation, t.occlusion, t.total, result.backend.c_str());
}

int cmdRun(const Arguments& args) {
  const std::string out = args.require("out");
  const io::PairPaths paths = inputPaths(args);
  if (!args.has("intrinsics") && !args.has("camera-info"))
    throw UsageError("missing --intrinsics FX,FY,CX,CY or --camera-info FILE");
  if (args.has("intrinsics")) io::parseIntrinsics(args.get("intrinsics"));  // report bad text before loading
  const Config config = buildConfig(args);
  const Result result = solveAndWrite(paths, args, config, out, nullptr, nullptr);
  printSegments(result);
  printTimings(result);
  std::printf("wrote %s\n", out.c_str());
  return 0;
}

int cmdSynth(const Arguments& args) {
  const std::string out = args.require("out");
  SyntheticSceneOptions options;
  if (args.has("variant")) options.variant = parseInteger("variant", args.get("variant"));
  if (args.has("width")) options.width = parseInteger("width", args.get("width"));
  if (args.has("height")) options.height = parseInteger("height", args.get("height"));
  if (args.has("seed")) options.seed = unsigned(parseInteger("seed", args.get("seed")));
  if (args.has("noise")) {
    options.intensity_noise = 0.01;  // about 2.5 grey levels
    options.depth_noise = 0.0015;    // [m] at 1 m, Kinect-like
  }
  if (options.variant < 0 || options.variant >= syntheticVariantCount())
    throw InputError("--variant " + std::to_string(options.variant) + ": expected 0.." +
                     std::to_string(syntheticVariantCount() - 1));
  if (options.width < 16 || options.height < 12)
    throw InputError("--width/--height " + std::to_string(options.width) + "x" + std::to_string(options.height) +
                     ": too small (at least 16x12)");
  progress("rendering variant " + std::to_string(options.variant) + " at " + std::to_string(options.width) + "x" +
           std::to_string(options.height) + "...");
  const SyntheticPair pair = renderSyntheticPair(options);
  io::writeSyntheticDirectory(out, pair);
  int moving = 0;
  for (const SyntheticPart& p : pair.parts) moving += p.twist.norm() > 0 ? 1 : 0;
  std::printf("wrote %s (intrinsics %s, %zu part(s), %d moving)\n", out.c_str(),
              io::formatIntrinsics(pair.intrinsics).c_str(), pair.parts.size(), moving);
  return 0;
}

io::EvalMetrics evaluateAndWrite(const std::string& result_dir, const io::GroundTruthFiles* truth,
                                 const io::LoadedPair* inputs, const Intrinsics* K) {
  const io::ResultFiles result = io::loadResultDirectory(result_dir);
  const io::EvalMetrics metrics = io::evaluateResult(result, truth, inputs, K);
  io::writeTextFile((std::filesystem::path(result_dir) / "eval.json").string(), io::evalJson(metrics));
  return metrics;
}

int cmdEval(const Arguments& args) {
  const std::string result_dir = args.require("result");
  io::GroundTruthFiles truth;
  const bool with_truth = args.has("gt");
  if (with_truth) truth = io::loadGroundTruthDirectory(args.get("gt"));

  io::LoadedPair inputs;
  Intrinsics K;
  bool with_inputs = false;
  if (args.has("rgb1") || args.has("depth1") || args.has("rgb2") || args.has("depth2")) {
    inputs = io::loadPair(inputPaths(args));
    K = inputIntrinsics(args, inputs.frame1.width(), inputs.frame1.height());
    with_inputs = true;
  } else if (with_truth && io::fileExists((std::filesystem::path(args.get("gt")) / "rgb1.png").string())) {
    const std::string gt = args.get("gt");
    inputs = io::loadPair(io::syntheticPairPaths(gt));
    K = io::parseIntrinsics(io::readTextFile((std::filesystem::path(gt) / "intrinsics.txt").string()));
    with_inputs = true;
  }
  if (!with_truth && !with_inputs)
    throw UsageError("nothing to evaluate against: give --gt DIR and/or the inputs (--rgb1 ... --intrinsics)");
  const io::EvalMetrics metrics =
      evaluateAndWrite(result_dir, with_truth ? &truth : nullptr, with_inputs ? &inputs : nullptr, with_inputs ? &K : nullptr);
  std::cout << io::evalTable(metrics);
  std::printf("wrote %s\n", (std::filesystem::path(result_dir) / "eval.json").string().c_str());
  return 0;
}

int cmdDemo(const Arguments& args) {
  const std::string out = args.require("out");
  SyntheticSceneOptions options;
  if (args.has("width")) options.width = parseInteger("width", args.get("width"));
  if (args.has("height")) options.height = parseInteger("height", args.get("height"));
  progress("rendering the synthetic pair (variant 0, " + std::to_string(options.width) + "x" +
           std::to_string(options.height) + ")...");
  const SyntheticPair pair = renderSyntheticPair(options);
  io::writeSyntheticDirectory(out, pair);

  Config config = buildConfig(args);
  Arguments run_args = args;
  run_args.values["intrinsics"] = io::formatIntrinsics(pair.intrinsics);
  io::LoadedPair loaded;
  Intrinsics K;
  const Result result = solveAndWrite(io::syntheticPairPaths(out), run_args, config, out, &loaded, &K);
  const io::GroundTruthFiles truth = io::loadGroundTruthDirectory(out);
  const io::EvalMetrics metrics = evaluateAndWrite(out, &truth, &loaded, &K);

  std::printf("ground truth: %zu part(s):\n", pair.parts.size());
  for (const SyntheticPart& p : pair.parts)
    std::printf("  part %2d %-16s |v| = %7.1f mm, |w| = %6.2f deg\n", p.id, p.name.c_str(),
                1000.0 * p.twist.head<3>().norm(), p.twist.tail<3>().norm() * 180.0 / M_PI);
  printSegments(result);
  std::printf("optical flow EPE %.3f px (zero flow %.3f px; moving pixels %.3f px, zero flow %.3f px), AAE %.2f deg,\n"
              "3D EPE %.1f mm, segmentation agreement %.3f, occlusion agreement %.3f\n",
              metrics.flow_epe, metrics.flow_epe_zero_flow, metrics.flow_epe_moving, metrics.flow_epe_moving_zero_flow,
              metrics.flow_aae_deg, 1000.0 * metrics.scene_flow_epe, metrics.segmentation_agreement,
              metrics.occlusion_agreement);
  printTimings(result);
  std::printf("wrote %s (see overview.png)\n", out.c_str());
  return 0;
}

std::vector<std::string> splitList(const std::string& text) {
  std::vector<std::string> items;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    if (comma > start) items.push_back(text.substr(start, comma - start));
    start = comma + 1;
  }
  return items;
}

int cmdBenchReal(const Arguments& args) {
  const std::string data = args.require("data");
  const Config config = buildConfig(args);
  const std::vector<std::string> pairs = args.has("pairs") ? splitList(args.get("pairs")) : io::realPairNames();
  if (pairs.empty()) throw UsageError("--pairs '" + args.get("pairs") + "' names no pair");
  const int repeat = args.has("repeat") ? parseInteger("repeat", args.get("repeat")) : 1;
  if (repeat < 1) throw InputError("--repeat " + std::to_string(repeat) + ": must be >= 1");
  io::ExclusionMask mask = io::ExclusionMask::UnionOfAll;
  if (args.has("mask")) {
    if (args.get("mask") == "mcflow") mask = io::ExclusionMask::McFlowOnly;
    else if (args.get("mask") != "union") throw InputError("--mask '" + args.get("mask") + "': expected union or mcflow");
  }
  const int halvings = args.has("full-resolution") ? 0 : 1;

  std::vector<io::PairScores> scores;
  std::string backend;
  for (const std::string& name : pairs) {
    progress("pair " + name + ": loading and solving (one label, MC-TV, MC-Quad; " + std::to_string(repeat) +
             " run(s) each)...");
    const io::RealPair pair = io::loadRealPair(data, name, halvings, config);
    const io::PairSolves solves = io::solveRealPair(pair, config, repeat);
    backend = solves.quad.backend;
    scores.push_back(io::scoreRealPair(pair, solves, mask));
  }
  std::printf("# mcflow bench-real: %s, %s input, processing level %d, backend %s, %d run(s) per solve (median "
              "times), excluded: %s\n",
              data.c_str(), halvings ? "320x240 (halved)" : "640x480", config.processing_level, backend.c_str(), repeat,
              mask == io::ExclusionMask::UnionOfAll ? "occlusions of all solves" : "occlusions of MC-Flow");
  std::fputs(io::realBenchTable(scores).c_str(), stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<Command> all = commands();
  if (argc < 2) {
    printMainUsage(std::cerr);
    return 2;
  }
  const std::string name = argv[1];
  if (name == "--help" || name == "-h" || name == "help") {
    printMainUsage(std::cout);
    return 0;
  }
  const Command* command = nullptr;
  for (const Command& c : all)
    if (c.name == name) command = &c;
  if (!command) {
    std::cerr << "mcflow: unknown command '" << name << "'\n\n";
    printMainUsage(std::cerr);
    return 2;
  }
  try {
    const Arguments args = parseArguments(*command, argc, argv, 2);
    if (args.has("help")) {
      printCommandUsage(*command, std::cout);
      return 0;
    }
    if (name == "run") return cmdRun(args);
    if (name == "synth") return cmdSynth(args);
    if (name == "eval") return cmdEval(args);
    if (name == "bench-real") return cmdBenchReal(args);
    return cmdDemo(args);
  } catch (const UsageError& e) {
    std::cerr << "mcflow " << name << ": " << e.what() << "\n\n";
    printCommandUsage(*command, std::cerr);
    return 2;
  } catch (const BackendError& e) {
    std::cerr << "mcflow " << name << ": backend error: " << e.what() << "\n";
    return 2;
  } catch (const InputError& e) {
    std::cerr << "mcflow " << name << ": input error: " << e.what() << "\n";
    return 1;
  } catch (const ConfigError& e) {
    std::cerr << "mcflow " << name << ": configuration error: " << e.what() << "\n";
    return 1;
  } catch (const io::FileError& e) {
    std::cerr << "mcflow " << name << ": file error: " << e.what() << "\n";
    return 1;
  } catch (const cv::Exception& e) {
    std::cerr << "mcflow " << name << ": OpenCV error: " << e.what() << "\n";
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    std::cerr << "mcflow " << name << ": file error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "mcflow " << name << ": internal error: " << e.what() << "\n";
    return 3;
  }
}
