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
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "mc_flow/cli/command_line.h"
#include "mc_flow/core/config.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/eval/metrics.h"
#include "mc_flow/eval/real_pairs.h"
#include "mc_flow/eval/sequence_folder.h"
#include "mc_flow/eval/synthetic_scene.h"
#include "mc_flow/io/benchmark.h"
#include "mc_flow/io/camera_info.h"
#include "mc_flow/io/config_file.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/resources.h"
#include "mc_flow/io/trajectory_eval.h"
#include "mc_flow/io/result_io.h"
#include "mc_flow/io/sequence_io.h"
#include "mc_flow/io/visualization.h"
#ifdef MCFLOW_WITH_ROSBAG
#include "mc_flow/ros/bag_sequence.h"
#endif

namespace {

using namespace mc_flow;

constexpr int kMaxImageSide = 16384;  // [px] --width/--height of the synthetic scenes

/// A subcommand: its help and its options (each subcommand parses its own CommandLine; a usage error exits 2).
struct Command {
  std::string name, synopsis, description;
  std::vector<CommandLineOption> options;
};

const std::vector<CommandLineOption> kInputOptions = {
    {"rgb1", true, "colour image of frame 1 (8-bit RGB/grey PNG/JPG/PPM/PGM, or 16-bit grey)"},
    {"depth1", true, "depth of frame 1: 16-bit PNG/PGM (see --depth-scale) or float PFM/EXR/TIFF in metres"},
    {"rgb2", true, "colour image of frame 2"},
    {"depth2", true, "depth of frame 2"},
    {"intrinsics", true, "FX,FY,CX,CY in pixels (e.g. 525,525,319.5,239.5)"},
    {"camera-info", true, "ROS camera_info YAML file (K, or P) instead of --intrinsics"},
    {"depth-scale", true, "16-bit depth units per metre (default 1000 = mm as ROS 16UC1; TUM data: 5000)"},
};

// The options of a sequence of image files (--tum, --frames), run-seq's and export-seq's.
const std::vector<CommandLineOption> kFileSequenceOptions = {
    {"tum", true, "TUM RGB-D directory (rgb.txt, depth.txt, optional associations.txt; depth 5000/m)"},
    {"frames", true, "directory with rgb/ and depth/ images paired in name order (depth 1000/m)"},
    {"fps", true, "frame rate of --frames [Hz] (default 30)"},
    {"camera-info", true, "ROS camera_info YAML file instead of --intrinsics"},
    {"max-frames", true, "stop after this many frames"},
};

std::vector<Command> commands() {
  std::vector<Command> list;
  Command run{
      "run",
      "mcflow run --rgb1 F --depth1 F --rgb2 F --depth2 F (--intrinsics FX,FY,CX,CY | --camera-info F) --out DIR",
      "Estimates piece-wise rigid scene flow between two RGB-D frames and writes optical_flow.flo, "
      "scene_flow.pfm, labels.png, soft_labels.npy, occlusion.png, segments.json, report.json, "
      "segmentation.png, flow.png and overview.png into DIR.",
      kInputOptions};
  for (const CommandLineOption& o : std::vector<CommandLineOption>{
           {"max-depth", true, "[m] depth beyond this is invalid (Config::max_depth)"},
           {"regularizer", true, "quad | tv"},
           {"labels", true, "initial number of labels (K-means clusters, Config::initial_labels)"},
           {"backend", true, "auto | cpu | cuda"},
           {"config", true, "JSON or YAML file of Config fields (keys = Config member names)"},
           {"set", true, "name=value: sets one Config field; may be repeated; overrides --config and flags", true},
           {"processing-level", true, "pyramid level the solver finishes at (0 = input resolution)"},
           {"out", true, "output directory (created)"},
           {"verbose", false, "progress of the solver on stderr"},
           {"help", false, "this help"}})
    run.options.push_back(o);
  list.push_back(run);

  Command run_seq{
      "run-seq",
      "mcflow run-seq (--tum DIR | --frames DIR | --bag FILE [--rgb-topic T --depth-topic T --info-topic T]) "
      "[--intrinsics FX,FY,CX,CY | --camera-info F] [--cold] --out DIR",
      "Solves every consecutive pair of an RGB-D sequence as a stream: each pair warm-starts from the "
      "previous one (unless --cold) and segments keep their ids. Writes DIR/pair_NNNN/ (the files of "
      "`mcflow run`; labels.png and segments.json hold the persistent ids; moving.png: 255 on pixels of "
      "segments that move relative to the static world), DIR/trajectories.csv (pair, stamp, id, vx, vy, "
      "vz, wx, wy, wz, support per segment and pair, then world, moving and the velocity relative to the "
      "static world), DIR/trajectory.txt (the camera's path in the TUM RGB-D format, the first frame at "
      "the identity: `mcflow eval-traj` scores it), DIR/odometry.csv (per pair with a static world the camera's "
      "motion, C2 = C1 exp(twist), and its covariance: `mcflow eval-traj --odometry` checks it), DIR/ids_over_time.png "
      "and "
      "DIR/sequence.json (per pair: start kind, timings, ids, merges, resets). A rosbag (--bag, ROS build "
      "only) is read as the nodelet reads its topics: colour and depth paired by the nearest header stamp, "
      "intrinsics from the first camera_info, frames with no valid depth skipped.",
      {{"bag", true, "rosbag with sensor_msgs/Image colour and depth (16UC1 mm or 32FC1 m) and CameraInfo"},
       {"rgb-topic", true, "colour topic of --bag (default /camera/rgb/image_rect_color)"},
       {"depth-topic", true, "registered depth topic of --bag (default /camera/depth_registered/image_rect)"},
       {"info-topic", true, "camera_info topic of --bag (default /camera/rgb/camera_info)"},
       {"max-stamp-difference", true,
        "[s] --bag: colour and depth stamps further apart are not paired "
        "(default 0.02)"},
       {"intrinsics", true,
        "FX,FY,CX,CY in pixels (default: DIR/camera_info.yaml when present; --bag: "
        "its first camera_info)"},
       {"depth-scale", true,
        "16-bit depth units per metre (default 5000 with --tum, 1000 with --frames; "
        "not with --bag: 16UC1 is mm)"},
       {"downsample", true, "input pixels per processing pixel: 0 = towards 320 px wide (default), or 1, 2, 4..."},
       {"max-pair-interval", true, "[s] a longer gap between frames starts a new sequence (default 1)"},
       {"cold", false, "solve every pair from scratch (ids are still matched by overlap)"}}};
  run_seq.options.insert(run_seq.options.begin(), kFileSequenceOptions.begin(), kFileSequenceOptions.end());
  // The solver options of `run` (not its pair inputs).
  for (const CommandLineOption& o : run.options) {
    bool input = false;
    for (const CommandLineOption& i : kInputOptions) input = input || i.name == o.name;
    if (!input) run_seq.options.push_back(o);
  }
  list.push_back(run_seq);

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
                   {"frames", true,
                    "N >= 2: a sequence of N frames in the TUM RGB-D layout (rgb/, depth/ at 5000 units "
                    "per metre, rgb.txt, depth.txt, camera_info.yaml) with ground truth per pair in "
                    "gt/pair_NNNN/; parts move smoothly, one starts moving at frame 10, one leaves the view"},
                   {"no-events", false,
                    "with --frames: without the box that starts late and the one that leaves the "
                    "view: the scene of the demo bag (make_synthetic_bag), for its ground truth"},
                   {"help", false, "this help"}}});

  Command eval{
      "eval",
      "mcflow eval --result DIR [--gt DIR] [input options]",
      "Evaluates a result: optical-flow EPE/AAE on non-occluded pixels, 3D EPE, segmentation and "
      "occlusion agreement (with --gt), and the RMSE of photometric and geometric residuals after "
      "warping frame 2 back (with the inputs; estimated occlusions excluded). With --gt pointing at "
      "a `mcflow synth` directory the inputs default to its files. Prints a table and writes "
      "DIR/eval.json.",
      {{"result", true, "directory written by `mcflow run`"}, {"gt", true, "directory written by `mcflow synth`"}}};
  for (const CommandLineOption& o : kInputOptions) eval.options.push_back(o);
  eval.options.push_back({"help", false, "this help"});
  list.push_back(eval);

  list.push_back({"demo",
                  "mcflow demo --out DIR",
                  "Renders the synthetic pair (variant 0), runs the solver on it, writes the inputs, the ground "
                  "truth, every output and eval.json into DIR, and prints a summary.",
                  {{"out", true, "output directory (created)"},
                   {"backend", true, "auto | cpu | cuda"},
                   {"width", true, "image width (default 320)"},
                   {"height", true, "image height (default 240)"},
                   {"verbose", false, "progress of the solver on stderr"},
                   {"help", false, "this help"}}});

  list.push_back(
      {"bench-real",
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
        {"set", true, "name=value: sets one Config field; may be repeated", true},
        {"processing-level", true, "pyramid level the solver finishes at (Config::processing_level)"},
        {"backend", true, "auto | cpu | cuda"},
        {"full-resolution", false, "keep the 640x480 input (default: halve to 320x240)"},
        {"mask", true, "union (default: occlusions of all three solves excluded) | mcflow (MC-Flow's only)"},
        {"repeat", true, "solves per method and pair; times are the median (default 1)"},
        {"verbose", false, "progress of the solver on stderr"},
        {"help", false, "this help"}}});

  list.push_back(
      {"eval-traj",
       "mcflow eval-traj --gt FILE --est FILE [--odometry FILE] [--max-difference S] [--offset S] [--plot PNG]",
       "Scores a camera trajectory (TUM RGB-D format: 'stamp tx ty tz qx qy qz qw' per line, e.g. run-seq's "
       "trajectory.txt) against ground truth (e.g. a TUM groundtruth.txt) as the TUM RGB-D benchmark does: "
       "ATE (RMSE of the positions after the rigid alignment that minimises it) and RPE (translation and "
       "rotation of the relative motion per frame and over about one second, RMSE). Estimated poses are "
       "matched to the nearest ground-truth stamp.",
       {{"gt", true, "ground-truth trajectory file"},
        {"est", true, "estimated trajectory file"},
        {"max-difference", true, "[s] largest stamp difference of a match (default 0.02)"},
        {"offset", true, "[s] added to the estimate's stamps before matching (default 0)"},
        {"plot", true, "PNG of both paths seen from above (x, z), the estimate aligned"},
        {"odometry", true,
         "run-seq's odometry.csv: also the NEES of each pair's camera motion against the ground truth's "
         "(chi-square with 6 degrees of freedom when the covariances are right)"},
        {"help", false, "this help"}}});

  list.push_back({"export-real",
                  "mcflow export-real --data DIR --out DIR",
                  "Writes the real pairs as the solver sees them (grey intensity in [0, 1] and depth in metres, "
                  "after the loader's depth cleaning) at 640x480 and halved to 320x240, as PFM files with their "
                  "intrinsics, for `mcflow_bench --real DIR` on a machine without OpenCV (the GPU machine): "
                  "OUT/<pair>_<W>x<H>/{intensity0,depth0,intensity1,depth1}.pfm and intrinsics.txt (fx fy cx cy).",
                  {{"data", true, "directory of the real pairs (e.g. $MCFLOW_SHARED_DATA/real_pairs)"},
                   {"out", true, "output directory (created)"},
                   {"pairs", true, "comma-separated folder names (default: the four pairs of the shared set)"},
                   {"help", false, "this help"}}});

  list.push_back(
      {"export-seq",
       "mcflow export-seq (--tum DIR | --frames DIR) [--intrinsics FX,FY,CX,CY | --camera-info F] --out DIR",
       "Writes an RGB-D sequence's frames as run-seq decodes them (grey intensity in [0, 1], depth in metres, at the "
       "input resolution) as PFM files with their stamps and intrinsics, for `mcflow_bench_stream --sequence DIR` on "
       "a machine without OpenCV (the GPU machine): OUT/intensity_NNNNN.pfm, OUT/depth_NNNNN.pfm, OUT/stamps.txt and "
       "OUT/intrinsics.txt (mc_flow/eval/sequence_folder.h).",
       {{"intrinsics", true, "FX,FY,CX,CY in pixels (default: DIR/camera_info.yaml when present)"},
        {"depth-scale", true, "16-bit depth units per metre (default 5000 with --tum, 1000 with --frames)"},
        {"out", true, "output directory (created)"},
        {"help", false, "this help"}}});
  list.back().options.insert(list.back().options.begin(), kFileSequenceOptions.begin(), kFileSequenceOptions.end());
  return list;
}

void printMainUsage(std::ostream& out) {
  out << "mcflow - piece-wise rigid scene flow from RGB-D pairs (MC-Flow, Jaimez et al. CVPR 2016)\n\n"
         "usage: mcflow <command> [options]     (mcflow <command> --help for its options)\n\ncommands:\n";
  for (const Command& c : commands()) out << "  " << c.synopsis << "\n";
  out << "\nexit codes: 0 success, 1 bad input/config/file, 2 usage error or unusable backend, 3 internal error\n";
}

/// The subcommand's own command line: only the options of its table (--set only where it declares it).
CommandLine commandLine(const Command& c) {
  return CommandLine("mcflow " + c.name, c.options, ConfigSettings::Refused);
}

void printCommandUsage(const Command& c, std::ostream& out) {
  out << "usage: " << c.synopsis << "\n\n" << c.description << "\n\noptions:\n" << commandLine(c).optionsHelp();
}

double elapsedMs(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

void progress(const std::string& message) { std::cerr << "mcflow: " << message << std::endl; }

/// --depth-scale: 16-bit depth units per metre (> 0), or `fallback`.
double depthScale(const CommandLine& args, double fallback) {
  const double scale = args.number("depth-scale", fallback);
  if (!(scale > 0)) throw CommandLineError("--depth-scale '" + args.text("depth-scale", "") + "': must be > 0");
  return scale;
}

io::PairPaths inputPaths(const CommandLine& args) {
  io::PairPaths paths;
  paths.rgb1 = args.required("rgb1");
  paths.depth1 = args.required("depth1");
  paths.rgb2 = args.required("rgb2");
  paths.depth2 = args.required("depth2");
  paths.depth_scale = depthScale(args, paths.depth_scale);
  return paths;
}

/// Where a pair's intrinsics come from: --intrinsics FX,FY,CX,CY or a --camera-info file (empty: not given).
struct IntrinsicsSource {
  std::string text, camera_info;
};

IntrinsicsSource intrinsicsSource(const CommandLine& args) {
  if (args.has("intrinsics") && args.has("camera-info"))
    throw CommandLineError("give either --intrinsics or --camera-info, not both");
  return {args.text("intrinsics", ""), args.text("camera-info", "")};
}

Intrinsics inputIntrinsics(const IntrinsicsSource& source, int width, int height) {
  if (!source.text.empty()) return io::parseIntrinsics(source.text);
  if (source.camera_info.empty()) throw CommandLineError("missing --intrinsics FX,FY,CX,CY or --camera-info FILE");
  const io::CameraInfo info = io::loadCameraInfo(source.camera_info);
  if (width > 0 && info.width > 0 && (info.width != width || info.height != height))
    std::cerr << "mcflow: warning: camera info '" << source.camera_info << "' is for " << info.width << "x"
              << info.height << " but the images are " << width << "x" << height << "\n";
  return info.intrinsics;
}

/// Config from --config, then the dedicated flags, then --set, then --verbose; validated.
Config buildConfig(const CommandLine& args) {
  Config config;
  if (args.has("config")) io::applyConfigFile(args.text("config", ""), config);
  config.max_depth = args.number("max-depth", config.max_depth);
  config.initial_labels = args.integer("labels", config.initial_labels);  // Config::validate checks the range
  config.processing_level = args.integer("processing-level", config.processing_level);
  try {
    if (args.has("regularizer")) config.regularizer = parseRegularizer(args.text("regularizer", ""));
  } catch (const ConfigError& e) {
    throw ConfigError("--regularizer '" + args.text("regularizer", "") + "': " + e.what());
  }
  try {
    if (args.has("backend")) config.backend = parseBackend(args.text("backend", ""));
  } catch (const ConfigError& e) {
    throw ConfigError("--backend '" + args.text("backend", "") + "': " + e.what());
  }
  args.applySettings(config);
  if (args.has("verbose")) config.verbose = true;
  try {
    config.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(std::string("invalid configuration: ") + e.what());
  }
  return config;
}

/// Loads, solves and writes one pair; returns the result.
Result solveAndWrite(const io::PairPaths& paths, const IntrinsicsSource& intrinsics, const Config& config,
                     const std::string& out, io::LoadedPair* loaded, Intrinsics* used_K) {
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
  const io::SizeCheck size =
      io::checkRunSize(pair.frame1.width(), pair.frame1.height(), config, solver.backendName() == "cpu", available);
  if (!size.error.empty()) throw InputError(size.error);
  if (!size.warning.empty()) std::cerr << "mcflow: warning: " << size.warning << std::endl;
  const Intrinsics K = inputIntrinsics(intrinsics, pair.frame1.width(), pair.frame1.height());
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
    std::printf("  segment %2d: |v| = %7.1f mm, |w| = %6.2f deg, support %8.0f px, centroid (%.2f, %.2f, %.2f) m%s\n",
                s.id, 1000.0 * s.twist.head<3>().norm(), s.twist.tail<3>().norm() * 180.0 / M_PI, s.support,
                s.centroid.x(), s.centroid.y(), s.centroid.z(), result.world.contains(s.id) ? ", static world" : "");
}

void printTimings(const Result& result) {
  const StageTimings& t = result.timings;
  std::printf("timings [ms]: init %.1f, motion %.1f, labels %.1f, adaptation %.1f, occlusion %.1f, total %.1f (%s)\n",
              t.initialisation, t.motion, t.labels, t.adaptation, t.occlusion, t.total, result.backend.c_str());
}

int cmdRun(const CommandLine& args) {
  const std::string out = args.required("out");
  const io::PairPaths paths = inputPaths(args);
  const IntrinsicsSource intrinsics = intrinsicsSource(args);
  if (intrinsics.text.empty() && intrinsics.camera_info.empty())
    throw CommandLineError("missing --intrinsics FX,FY,CX,CY or --camera-info FILE");
  if (!intrinsics.text.empty()) io::parseIntrinsics(intrinsics.text);  // report bad text before loading
  const Config config = buildConfig(args);
  const Result result = solveAndWrite(paths, intrinsics, config, out, nullptr, nullptr);
  printSegments(result);
  printTimings(result);
  std::printf("wrote %s\n", out.c_str());
  return 0;
}

/// One frame as run-seq reads it: the stream frame (its `extra` is the colour picture at the processing
/// resolution, for the pictures only) and the names report.json gives its inputs.
struct SequenceInput {
  StreamFrame stream;
  std::string rgb_name, depth_name;
};

/// A frame the source skips (a bag's frame with no valid depth, as the nodelet skips it); the run goes on.
struct SkippedFrame : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Where run-seq's frames come from: a folder of files or a bag.
struct SequenceSource {
  std::string name;  // the sequence's stream source (a change would start a new sequence)
  std::size_t count = 0;
  std::function<SequenceInput(std::size_t)> load;  // throws SkippedFrame, or an error that ends the run
  int pipeline_downsample = 0;  // the pipeline's request: a bag's frames come already downsampled (1)
  double depth_scale = 1000.0;  // report.json: units per metre of 16-bit depth
};

/// --max-frames N (at least 2), or -1: all frames.
int maxFrames(const CommandLine& args) { return args.integer("max-frames", -1, 2, std::numeric_limits<int>::max()); }

/// --tum DIR or --frames DIR: image files, downsampled by the pipeline.
SequenceSource fileSequence(const CommandLine& args, int downsample) {
  const std::string dir = args.has("tum") ? args.text("tum", "") : args.text("frames", "");
  const double fps = args.number("fps", 30.0);
  auto frames = std::make_shared<std::vector<io::SequenceFrameFiles>>(
      args.has("tum") ? io::listTumSequence(dir) : io::listNumberedFrames(dir, fps));
  const int max_frames = maxFrames(args);
  if (max_frames > 0 && int(frames->size()) > max_frames) frames->resize(std::size_t(max_frames));
  if (frames->size() < 2)
    throw InputError("sequence '" + dir + "' has " + std::to_string(frames->size()) + " frame(s)");
  const double depth_scale = depthScale(args, args.has("tum") ? 5000.0 : 1000.0);
  IntrinsicsSource intrinsics = intrinsicsSource(args);
  const std::string default_info = (std::filesystem::path(dir) / "camera_info.yaml").string();
  if (intrinsics.text.empty() && intrinsics.camera_info.empty()) {
    if (!io::fileExists(default_info))
      throw CommandLineError("missing --intrinsics FX,FY,CX,CY or --camera-info FILE (and no " + default_info + ")");
    intrinsics.camera_info = default_info;
  }
  auto K = std::make_shared<std::optional<Intrinsics>>();
  SequenceSource source;
  source.name = dir;
  source.count = frames->size();
  source.pipeline_downsample = downsample;
  source.depth_scale = depth_scale;
  source.load = [=](std::size_t i) {
    const io::SequenceFrameFiles& f = (*frames)[i];
    SequenceInput in;
    ImageU8 colour;
    in.stream.frame = io::loadRgbdFrame(f.rgb, f.depth, depth_scale, &colour);
    if (!*K) *K = inputIntrinsics(intrinsics, in.stream.frame.width(), in.stream.frame.height());
    in.stream.K = **K;
    in.stream.stamp = f.stamp;
    in.stream.source = dir;
    // The colour at the processing resolution, for the pictures only.
    const int factor = chooseDownsample(downsample, in.stream.frame.width());
    if (factor > 1) {
      cv::Mat small;
      cv::resize(io::toMat(colour), small,
                 cv::Size(in.stream.frame.width() / factor, in.stream.frame.height() / factor), 0, 0, cv::INTER_AREA);
      colour.width = small.cols;
      colour.height = small.rows;
      colour.data.assign(small.data, small.data + small.total() * 3);
    }
    in.stream.extra = std::move(colour);
    in.rgb_name = f.rgb;
    in.depth_name = f.depth;
    return in;
  };
  return source;
}

/// --bag FILE: the nodelet's message conversion (it downsamples, so the pipeline does not).
SequenceSource bagSequence(const CommandLine& args, const Config& config, int downsample) {
#ifdef MCFLOW_WITH_ROSBAG
  if (args.has("depth-scale"))
    throw CommandLineError(
        "--depth-scale is for --tum/--frames: a bag's depth is 16UC1 in millimetres or 32FC1 in metres "
        "(REP 118), read as the nodelet reads it");
  if (args.has("fps")) throw CommandLineError("--fps is for --frames: a bag's frames carry their stamps");
  mc_flow_ros::BagReadOptions options;
  options.topics.rgb = args.text("rgb-topic", options.topics.rgb);
  options.topics.depth = args.text("depth-topic", options.topics.depth);
  options.topics.info = args.text("info-topic", options.topics.info);
  options.max_stamp_difference = args.number("max-stamp-difference", options.max_stamp_difference);
  if (!(options.max_stamp_difference >= 0))
    throw CommandLineError("--max-stamp-difference '" + args.text("max-stamp-difference", "") + "': must be >= 0");
  // --intrinsics / --camera-info are for the bag's images as they are (0x0: inputIntrinsics checks no size).
  if (args.has("intrinsics") || args.has("camera-info"))
    options.intrinsics = inputIntrinsics(intrinsicsSource(args), 0, 0);
  options.downsample = downsample;
  options.depth_range = config.depth_downsample_range;
  const std::string path = args.text("bag", "");
  auto bag = std::make_shared<mc_flow_ros::BagSequence>(path, options);
  progress(bag->summary());
  SequenceSource source;
  source.name = path;
  source.count = bag->size();
  const int max_frames = maxFrames(args);
  if (max_frames > 0 && int(source.count) > max_frames) source.count = std::size_t(max_frames);
  if (source.count < 2) throw InputError("bag '" + path + "' has " + std::to_string(source.count) + " paired frame(s)");
  source.pipeline_downsample = 1;
  source.depth_scale = 1000.0;  // 16UC1: millimetres
  source.load = [bag](std::size_t i) {
    mc_flow_ros::BagFrame f;
    try {
      f = bag->frame(i);
    } catch (const mc_flow_ros::FrameInputError& e) {
      // A camera's first frames often have no depth yet: skipped, as the nodelet skips them. Anything else
      // (encoding, layout, sizes) is the stream's and would fail every frame: the run stops naming it.
      if (e.problem == mc_flow_ros::InputProblem::Depth) throw SkippedFrame(e.what());
      throw;
    }
    SequenceInput in;
    in.stream = std::move(f.frame);
    in.stream.extra = std::move(f.colour);
    in.rgb_name = f.rgb_name;
    in.depth_name = f.depth_name;
    return in;
  };
  return source;
#else
  (void)args;
  (void)config;
  (void)downsample;
  throw CommandLineError(
      "--bag needs the ROS build: this mcflow was built without ROS (MCFLOW_WITH_ROS=OFF or catkin not "
      "found), so it cannot read rosbags; rebuild with ROS (scripts/build.sh) or export the bag's frames "
      "to a folder and use --tum/--frames");
#endif
}

int cmdRunSeq(const CommandLine& args) {
  const std::string out = args.required("out");
  if (int(args.has("tum")) + int(args.has("frames")) + int(args.has("bag")) != 1)
    throw CommandLineError("give one of --tum DIR, --frames DIR or --bag FILE");
  if (!args.has("bag"))
    for (const char* option : {"rgb-topic", "depth-topic", "info-topic", "max-stamp-difference"})
      if (args.has(option)) throw CommandLineError(std::string("--") + option + " is for --bag");
  Config config = buildConfig(args);
  if (args.has("cold")) config.warm_start = false;
  const int downsample = args.integer("downsample", 0);  // SequencePipeline checks it
  const double max_interval = args.number("max-pair-interval", 1.0);
  const SequenceSource source =
      args.has("bag") ? bagSequence(args, config, downsample) : fileSequence(args, downsample);
  io::createOutputDirectory(out);
  SequencePipeline pipeline(config, source.pipeline_downsample, max_interval);
  if (!pipeline.backendUnavailable().empty())  // the pipeline solves on the CPU rather than not at all
    progress("warning: backend '" + toString(config.backend) + "' cannot be used: running on the CPU (" +
             pipeline.backendUnavailable() + ")");

  std::string csv = io::trajectoryCsvHeader();
  std::string odometry = io::odometryCsvHeader();  // each solved pair's camera motion and its covariance
  std::string trajectory;                          // TUM RGB-D format: the camera's optical frame in the first frame's
  std::vector<std::vector<std::pair<int, double>>> ids_per_pair;
  std::ostringstream log;
  log << "[\n";
  int solved = 0, warm = 0, fallbacks = 0, failed = 0, skipped = 0;
  double total_ms = 0;
  std::string previous_rgb, previous_depth;  // the names of the pipeline's last frame
  const auto start = std::chrono::steady_clock::now();
  for (std::size_t i = 0; i < source.count; ++i) {
    SequenceInput in;
    try {
      in = source.load(i);
    } catch (const SkippedFrame& e) {
      ++skipped;
      progress(std::string("skipped: ") + e.what());
      continue;
    }
    const SequenceStep step = pipeline.push(std::move(in.stream));
    const std::string first_rgb = previous_rgb, first_depth = previous_depth;
    if (step.outcome != SequenceStep::Outcome::RepeatedStamp) {
      previous_rgb = in.rgb_name;
      previous_depth = in.depth_name;
    }
    if (!step.reset_key.empty()) progress("frame " + std::to_string(i) + ": new sequence: " + step.reset_reason);
    if (step.outcome == SequenceStep::Outcome::RepeatedStamp)
      progress("frame " + std::to_string(i) + ": dropped: its stamp repeats the previous frame's");
    if (step.outcome == SequenceStep::Outcome::PairFailed) {
      ++failed;
      progress("frame " + std::to_string(i) + ": pair skipped: " + step.problem);
    }
    if (step.outcome != SequenceStep::Outcome::Solved) continue;
    const Result& r = *step.result;
    ++solved;
    warm += r.start == StartKind::Warm;
    fallbacks += r.start == StartKind::ColdFallback;
    total_ms += r.timings.total;
    char name[32];
    std::snprintf(name, sizeof(name), "pair_%04ld", step.pair_index);
    io::LoadedPair loaded{step.first->frame, step.second->frame, std::any_cast<const ImageU8&>(step.first->extra),
                          std::any_cast<const ImageU8&>(step.second->extra)};
    io::RunInfo info{first_rgb, first_depth, in.rgb_name, in.depth_name, source.depth_scale, 0, 0};
    io::writeResultDirectory((std::filesystem::path(out) / name).string(), r, config, loaded, info);
    csv += io::trajectoryCsvRows(step.pair_index, step.second->stamp, r, &step.world_velocities);
    io::saveMask((std::filesystem::path(out) / name / "moving.png").string(), movingMask(r, step.world_velocities));
    // The camera's path: its first frame at the identity, then each solved pair's frame 2.
    if (trajectory.empty()) trajectory = io::tumTrajectoryLine(step.first->stamp, Eigen::Matrix4d::Identity());
    trajectory += io::tumTrajectoryLine(step.second->stamp, pipeline.odometry().pose);
    if (r.world.found) {
      OdometryStep camera;  // the camera moved by the inverse of the world's motion; the same covariance
      camera.first = step.first->stamp;
      camera.second = step.second->stamp;
      camera.twist = -r.world.twist;
      camera.covariance = r.world.covariance;
      odometry += io::odometryCsvRow(step.pair_index, camera);
    }
    std::vector<std::pair<int, double>> ids;
    for (const Segment& s : r.segments) ids.emplace_back(s.id, s.support);
    ids_per_pair.push_back(ids);
    log << (solved > 1 ? ",\n" : "") << "  {\"pair\": " << step.pair_index << ", \"stamp\": " << step.second->stamp
        << ", \"start\": \"" << toString(r.start) << "\", \"total_ms\": " << r.timings.total << ", \"ids\": [";
    for (std::size_t k = 0; k < r.segments.size(); ++k) log << (k ? ", " : "") << r.segments[k].id;
    log << "], \"merged\": [";
    for (std::size_t k = 0; k < r.merged_ids.size(); ++k)
      log << (k ? ", " : "") << "[" << r.merged_ids[k].first << ", " << r.merged_ids[k].second << "]";
    log << "], \"ended\": [";
    for (std::size_t k = 0; k < r.ended_ids.size(); ++k) log << (k ? ", " : "") << r.ended_ids[k];
    // How well the pair's flow explains frame 2 (Table 1's residuals; every pixel with depth that stays in view, so
    // that runs with other settings are scored on the same pixels).
    const ResidualRmse residual =
        warpResidualRmse(step.first->frame, step.second->frame, step.first->K, &r.scene_flow, nullptr);
    log << "], \"rmse_intensity\": " << residual.photometric << ", \"rmse_depth_m\": " << residual.geometric << "}";
    // Progress bar: pairs done of the frames' pairs, mean time per pair.
    const int width = 30, done = int((i * width) / (source.count - 1));
    std::fprintf(stderr, "\rmcflow: [%s%s] %d/%zu pairs, %.0f ms/pair (%s)   ",
                 std::string(std::size_t(done), '#').c_str(), std::string(std::size_t(width - done), ' ').c_str(),
                 solved, source.count - 1, total_ms / solved, toString(r.start).c_str());
  }
  std::fprintf(stderr, "\n");
  log << "\n]\n";
  io::writeTextFile((std::filesystem::path(out) / "trajectories.csv").string(), csv);
  io::writeTextFile((std::filesystem::path(out) / "odometry.csv").string(), odometry);
  io::writeTextFile((std::filesystem::path(out) / "trajectory.txt").string(),
                    "# mcflow run-seq: the colour camera's optical frame (x right, y down, z forward) in the first "
                    "frame's, from the static world's motion per pair\n# timestamp tx ty tz qx qy qz qw\n" +
                        trajectory);
  io::writeTextFile((std::filesystem::path(out) / "sequence.json").string(), log.str());
  if (!ids_per_pair.empty())
    io::writeImage((std::filesystem::path(out) / "ids_over_time.png").string(), io::idsOverTimeImage(ids_per_pair));
  const std::string skipped_text = skipped ? ", " + std::to_string(skipped) + " frame(s) skipped" : "";
  std::printf(
      "%d pair(s) solved (%d warm, %d cold fallbacks, %d failed, %ld new sequence(s)%s), %.1f ms/pair solving, "
      "%.1f s in all; wrote %s\n",
      solved, warm, fallbacks, failed, pipeline.resets(), skipped_text.c_str(), solved ? total_ms / solved : 0.0,
      elapsedMs(start) / 1000.0, out.c_str());
  return solved > 0 ? 0 : 1;
}

int cmdSynthSequence(const CommandLine& args, SyntheticSceneOptions options, int frame_count) {
  const std::string out = args.required("out");
  options.stream_events = !args.has("no-events");
  const double tum_scale = 5000.0, fps = 30.0;
  io::createOutputDirectory(out);
  std::filesystem::create_directories(std::filesystem::path(out) / "rgb");
  std::filesystem::create_directories(std::filesystem::path(out) / "depth");
  std::string rgb_list = "# timestamp filename\n", depth_list = "# timestamp filename\n";
  Intrinsics K;
  for (int t = 0; t < frame_count; ++t) {
    RgbdFrame frame;
    ImageU8 colour;
    renderSyntheticFrame(options, t, frame, colour, K);
    char name[32], stamp[32];
    std::snprintf(name, sizeof(name), "%04d.png", t);
    std::snprintf(stamp, sizeof(stamp), "%.6f", double(t) / fps);
    io::saveRgb((std::filesystem::path(out) / "rgb" / name).string(), colour);
    io::saveDepthPng16((std::filesystem::path(out) / "depth" / name).string(), frame.depth, tum_scale);
    rgb_list += std::string(stamp) + " rgb/" + name + "\n";
    depth_list += std::string(stamp) + " depth/" + name + "\n";
    if (t + 1 < frame_count) {
      options.first_frame = t;
      char pair[32];
      std::snprintf(pair, sizeof(pair), "pair_%04d", t);
      io::writeSyntheticDirectory((std::filesystem::path(out) / "gt" / pair).string(), renderSyntheticPair(options));
    }
    std::fprintf(stderr, "\rmcflow: rendered %d/%d frames", t + 1, frame_count);
  }
  std::fprintf(stderr, "\n");
  io::writeTextFile((std::filesystem::path(out) / "rgb.txt").string(), rgb_list);
  io::writeTextFile((std::filesystem::path(out) / "depth.txt").string(), depth_list);
  io::saveCameraInfo((std::filesystem::path(out) / "camera_info.yaml").string(), {K, options.width, options.height});
  std::printf(
      "wrote %s: %d frames in the TUM RGB-D layout (depth 5000 units/m), ground truth per pair in gt/; "
      "run `mcflow run-seq --tum %s --out DIR`\n",
      out.c_str(), frame_count, out.c_str());
  return 0;
}

int cmdSynth(const CommandLine& args) {
  const std::string out = args.required("out");
  SyntheticSceneOptions options;
  options.variant = args.integer("variant", options.variant, 0, syntheticVariantCount() - 1);
  options.width = args.integer("width", options.width, 16, kMaxImageSide);
  options.height = args.integer("height", options.height, 12, kMaxImageSide);
  if (args.has("seed")) options.seed = unsigned(args.integer("seed", 0));
  if (args.has("noise")) options.addSensorNoise();
  if (args.has("frames"))
    return cmdSynthSequence(args, options, args.integer("frames", 0, 2, std::numeric_limits<int>::max()));
  if (args.has("no-events")) throw CommandLineError("--no-events is for sequences (--frames N)");
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

int cmdEval(const CommandLine& args) {
  const std::string result_dir = args.required("result");
  io::GroundTruthFiles truth;
  const bool with_truth = args.has("gt");
  if (with_truth) truth = io::loadGroundTruthDirectory(args.text("gt", ""));

  io::LoadedPair inputs;
  Intrinsics K;
  bool with_inputs = false;
  if (args.has("rgb1") || args.has("depth1") || args.has("rgb2") || args.has("depth2")) {
    inputs = io::loadPair(inputPaths(args));
    K = inputIntrinsics(intrinsicsSource(args), inputs.frame1.width(), inputs.frame1.height());
    with_inputs = true;
  } else if (with_truth && io::fileExists((std::filesystem::path(args.text("gt", "")) / "rgb1.png").string())) {
    const std::string gt = args.text("gt", "");
    inputs = io::loadPair(io::syntheticPairPaths(gt));
    K = io::parseIntrinsics(io::readTextFile((std::filesystem::path(gt) / "intrinsics.txt").string()));
    with_inputs = true;
  }
  if (!with_truth && !with_inputs)
    throw CommandLineError("nothing to evaluate against: give --gt DIR and/or the inputs (--rgb1 ... --intrinsics)");
  const io::EvalMetrics metrics = evaluateAndWrite(result_dir, with_truth ? &truth : nullptr,
                                                   with_inputs ? &inputs : nullptr, with_inputs ? &K : nullptr);
  std::cout << io::evalTable(metrics);
  std::printf("wrote %s\n", (std::filesystem::path(result_dir) / "eval.json").string().c_str());
  return 0;
}

int cmdDemo(const CommandLine& args) {
  const std::string out = args.required("out");
  SyntheticSceneOptions options;
  options.width = args.integer("width", options.width, 16, kMaxImageSide);
  options.height = args.integer("height", options.height, 12, kMaxImageSide);
  progress("rendering the synthetic pair (variant 0, " + std::to_string(options.width) + "x" +
           std::to_string(options.height) + ")...");
  const SyntheticPair pair = renderSyntheticPair(options);
  io::writeSyntheticDirectory(out, pair);

  Config config = buildConfig(args);
  io::LoadedPair loaded;
  Intrinsics K;
  const Result result =
      solveAndWrite(io::syntheticPairPaths(out), {io::formatIntrinsics(pair.intrinsics), ""}, config, out, &loaded, &K);
  const io::GroundTruthFiles truth = io::loadGroundTruthDirectory(out);
  const io::EvalMetrics metrics = evaluateAndWrite(out, &truth, &loaded, &K);

  std::printf("ground truth: %zu part(s):\n", pair.parts.size());
  for (const SyntheticPart& p : pair.parts)
    std::printf("  part %2d %-16s |v| = %7.1f mm, |w| = %6.2f deg\n", p.id, p.name.c_str(),
                1000.0 * p.twist.head<3>().norm(), p.twist.tail<3>().norm() * 180.0 / M_PI);
  printSegments(result);
  std::printf(
      "optical flow EPE %.3f px (zero flow %.3f px; moving pixels %.3f px, zero flow %.3f px), AAE %.2f deg,\n"
      "3D EPE %.1f mm, segmentation agreement %.3f, occlusion agreement %.3f\n",
      metrics.flow_epe, metrics.flow_epe_zero_flow, metrics.flow_epe_moving, metrics.flow_epe_moving_zero_flow,
      metrics.flow_aae_deg, 1000.0 * metrics.scene_flow_epe, metrics.segmentation_agreement,
      metrics.occlusion_agreement);
  printTimings(result);
  std::printf("wrote %s (see overview.png)\n", out.c_str());
  return 0;
}

/// --pairs A,B (at least one name), or the pairs of the shared set.
std::vector<std::string> realPairSelection(const CommandLine& args) {
  if (!args.has("pairs")) return realPairNames();
  const std::vector<std::string> pairs = args.list("pairs", "");
  if (pairs.empty()) throw CommandLineError("--pairs '" + args.text("pairs", "") + "' names no pair");
  return pairs;
}

int cmdExportReal(const CommandLine& args) {
  const std::string data = args.required("data"), out = args.required("out");
  const std::vector<std::string> pairs = realPairSelection(args);
  const Config config;  // the loader's depth cleaning and halving use the default depth range, as bench-real
  for (const std::string& name : pairs)
    for (int halvings = 0; halvings <= 1; ++halvings) {
      const RealPair pair = io::loadRealPair(data, name, halvings, config);
      const std::string dir =
          out + "/" + name + "_" + std::to_string(pair.frame1.width()) + "x" + std::to_string(pair.frame1.height());
      writeRealPairFolder(dir, pair);
      std::printf("%s\n", dir.c_str());
    }
  return 0;
}

int cmdExportSeq(const CommandLine& args) {
  const std::string out = args.required("out");
  if (int(args.has("tum")) + int(args.has("frames")) != 1)
    throw CommandLineError("give one of --tum DIR or --frames DIR");
  const SequenceSource source = fileSequence(args, 1);  // the input resolution: the bench's pipeline downsamples
  // An earlier export's index goes first: an export that fails half way leaves no folder that reads as complete.
  std::filesystem::remove(std::filesystem::path(out) / "stamps.txt");
  std::vector<double> stamps;
  Intrinsics K;
  for (std::size_t i = 0; i < source.count; ++i) {
    const SequenceInput in = source.load(i);
    if (i == 0) K = in.stream.K;
    writeSequenceFrame(out, i, in.stream.frame);
    stamps.push_back(in.stream.stamp);
  }
  writeSequenceIndex(out, K, stamps);
  std::printf("%s: %zu frames\n", out.c_str(), stamps.size());
  return 0;
}

int cmdBenchReal(const CommandLine& args) {
  const std::string data = args.required("data");
  const Config config = buildConfig(args);
  const std::vector<std::string> pairs = realPairSelection(args);
  const int repeat = args.integer("repeat", 1, 1, std::numeric_limits<int>::max());
  const std::string mask_text = args.text("mask", "union");
  if (mask_text != "union" && mask_text != "mcflow")
    throw CommandLineError("--mask '" + mask_text + "': expected union or mcflow");
  const ExclusionMask mask = mask_text == "mcflow" ? ExclusionMask::McFlowOnly : ExclusionMask::UnionOfAll;
  const int halvings = args.has("full-resolution") ? 0 : 1;

  std::string backend;
  const std::vector<PairScores> scores = benchRealPairs(
      pairs, [&](const std::string& name) { return io::loadRealPair(data, name, halvings, config); }, config, repeat,
      mask, progress, &backend);
  std::printf(
      "# mcflow bench-real: %s, %s input, processing level %d, backend %s, %d run(s) per solve (median "
      "times), excluded: %s\n",
      data.c_str(), halvings ? "320x240 (halved)" : "640x480", config.processing_level, backend.c_str(), repeat,
      mask == ExclusionMask::UnionOfAll ? "occlusions of all solves" : "occlusions of MC-Flow");
  std::fputs(realBenchTable(scores).c_str(), stdout);
  return 0;
}

}  // namespace

int cmdEvalTraj(const CommandLine& args) {
  if (!args.has("gt") || !args.has("est")) throw CommandLineError("eval-traj needs --gt FILE and --est FILE");
  const double max_difference = args.number("max-difference", 0.02);
  const double offset = args.number("offset", 0.0);
  const io::StampedPoses gt = io::readTumTrajectory(args.text("gt", ""));
  const io::StampedPoses est = io::readTumTrajectory(args.text("est", ""));
  const io::TrajectoryErrors e = io::evaluateTrajectory(gt, est, max_difference, offset);
  std::printf("# mcflow eval-traj: %s against %s (%d of %zu poses matched within %.3f s, offset %.3f s)\n",
              args.text("est", "").c_str(), args.text("gt", "").c_str(), e.matched, est.size(), max_difference, offset);
  std::printf(
      "ate_rmse_m %.4f\nrpe_frame_trans_m %.4f\nrpe_frame_rot_deg %.3f\nrpe_second_trans_m %.4f\n"
      "rpe_second_rot_deg %.3f\n",
      e.ate_rmse_m, e.rpe_frame_trans_m, e.rpe_frame_rot_deg, e.rpe_second_trans_m, e.rpe_second_rot_deg);
  if (e.rpe_second_pairs == 0) std::printf("# the trajectory spans less than 1 s: no per-second RPE\n");
  if (args.has("plot")) io::writeImage(args.text("plot", ""), io::trajectoryPlot(e));
  if (args.has("odometry")) {
    // run-seq writes no step for a pair without a static world (the pose is held there): say how many are missing.
    const std::vector<OdometryStep> steps = io::readOdometryCsv(args.text("odometry", ""));
    const OdometryConsistency c = odometryConsistency(gt, steps, max_difference, offset);
    std::printf(
        "# odometry covariance: %d of %zu steps matched (the trajectory has %zu consecutive pairs); consistent: median "
        "near 5.35, mean within [%.2f, %.2f], 0.95 inside chi2_6's central 95 %%\nnees_median %.2f\nnees_mean "
        "%.2f\nnees_inside95 %.2f\n",
        c.matched, steps.size(), est.empty() ? std::size_t(0) : est.size() - 1, c.mean_low, c.mean_high, c.nees_median,
        c.nees_mean, c.inside95);
  }
  return 0;
}

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
  CommandLine args = commandLine(*command);
  try {
    args.parse(argc - 1, argv + 1);  // argv[1], the command, stands where parse expects the program
    if (args.helpRequested()) {
      printCommandUsage(*command, std::cout);
      return 0;
    }
    if (name == "run") return cmdRun(args);
    if (name == "run-seq") return cmdRunSeq(args);
    if (name == "synth") return cmdSynth(args);
    if (name == "eval") return cmdEval(args);
    if (name == "bench-real") return cmdBenchReal(args);
    if (name == "export-real") return cmdExportReal(args);
    if (name == "export-seq") return cmdExportSeq(args);
    if (name == "eval-traj") return cmdEvalTraj(args);
    return cmdDemo(args);
  } catch (const CommandLineError& e) {
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
