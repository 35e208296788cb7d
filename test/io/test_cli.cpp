// The `mcflow` tool as a subprocess: synth -> run -> eval end to end, and bad inputs (exit code != 0 and
// stderr naming the offending file or value).
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "mc_flow/io/camera_info.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"
#include "mc_flow/io/sequence_io.h"
#include "temp_dir.h"

#ifndef MCFLOW_CLI_PATH
#error "MCFLOW_CLI_PATH must name the mcflow binary"
#endif

namespace fs = std::filesystem;
using namespace mc_flow;

namespace {

constexpr int kWidth = 160, kHeight = 120;

struct CliRun {
  int code = -1;
  std::string out, err;
};

fs::path workDir() {
  static const test::TempDir dir("mcflow_cli_");
  return dir.path();
}

std::string quote(const std::string& s) { return "'" + s + "'"; }

CliRun runCli(const std::string& arguments) {
  static int counter = 0;
  const std::string tag = std::to_string(counter++);
  const std::string out = (workDir() / ("stdout_" + tag)).string(), err = (workDir() / ("stderr_" + tag)).string();
  const std::string command = quote(MCFLOW_CLI_PATH) + " " + arguments + " >" + quote(out) + " 2>" + quote(err);
  const int status = std::system(command.c_str());
  CliRun run;
  run.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.out = io::readTextFile(out);
  run.err = io::readTextFile(err);
  return run;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

// Value of a top-level numeric key in a JSON file we wrote ("key": number, or null -> NaN).
double jsonNumber(const std::string& text, const std::string& key) {
  const std::size_t k = text.find("\"" + key + "\":");
  if (k == std::string::npos) return std::nan("");
  const char* value = text.c_str() + k + key.size() + 3;
  while (*value == ' ') ++value;
  if (std::string(value, 4) == "null") return std::nan("");
  char* end = nullptr;
  const double v = std::strtod(value, &end);
  return end == value ? std::nan("") : v;
}

bool pythonJsonValid(const std::string& path) {
  if (std::system("python3 -c 'import json' >/dev/null 2>&1") != 0) return true;  // no python: not checkable here
  return std::system(("python3 -c 'import json,sys; json.load(open(sys.argv[1]))' " + quote(path)).c_str()) == 0;
}

/// A synthetic pair rendered once for all tests of this file.
const fs::path& synthDir() {
  static const fs::path dir = [] {
    const fs::path d = workDir() / "synth";
    const CliRun run = runCli("synth --out " + quote(d.string()) + " --width " + std::to_string(kWidth) + " --height " +
                              std::to_string(kHeight));
    EXPECT_EQ(run.code, 0) << run.err;
    return d;
  }();
  return dir;
}

std::string intrinsicsText() {
  std::string text = io::readTextFile((synthDir() / "intrinsics.txt").string());
  text.erase(text.find_last_not_of(" \n\r") + 1);
  return text;
}

std::string inputArgs(const std::string& depth_ext = ".png") {
  const fs::path& s = synthDir();
  return "--rgb1 " + quote((s / "rgb1.png").string()) + " --depth1 " + quote((s / ("depth1" + depth_ext)).string()) +
         " --rgb2 " + quote((s / "rgb2.png").string()) + " --depth2 " + quote((s / ("depth2" + depth_ext)).string());
}

void expectImage(const fs::path& path, int type, int width, int height) {
  const cv::Mat m = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(m.empty()) << path;
  EXPECT_EQ(m.type(), type) << path;
  EXPECT_EQ(m.cols, width) << path;
  EXPECT_EQ(m.rows, height) << path;
}

// Runs the solver on the shared pair and evaluates it; returns eval.json's text.
std::string runAndEvaluate(const std::string& name, const std::string& input_and_intrinsics) {
  const fs::path out = workDir() / name;
  const CliRun run = runCli("run " + input_and_intrinsics + " --out " + quote(out.string()));
  EXPECT_EQ(run.code, 0) << run.err;
  const CliRun eval = runCli("eval --result " + quote(out.string()) + " --gt " + quote(synthDir().string()));
  EXPECT_EQ(eval.code, 0) << eval.err;
  EXPECT_NE(eval.out.find("optical flow EPE"), std::string::npos) << eval.out;
  return io::readTextFile((out / "eval.json").string());
}

// The solver must recover most of the motion: on moving pixels its flow error must be below half of the error of
// predicting no motion (i.e. below half the mean true flow length there), and over all non-occluded pixels and in
// 3D it must beat the zero-flow prediction.
void expectRecoversMotion(const std::string& eval_json) {
  const double epe = jsonNumber(eval_json, "optical_flow_epe_px");
  const double epe_zero = jsonNumber(eval_json, "optical_flow_epe_zero_flow_px");
  const double moving = jsonNumber(eval_json, "optical_flow_epe_moving_px");
  const double moving_zero = jsonNumber(eval_json, "optical_flow_epe_moving_zero_flow_px");
  const double epe3d = jsonNumber(eval_json, "scene_flow_epe_m");
  const double epe3d_zero = jsonNumber(eval_json, "scene_flow_epe_zero_flow_m");
  ASSERT_TRUE(std::isfinite(epe) && std::isfinite(moving) && std::isfinite(epe3d)) << eval_json;
  EXPECT_GT(moving_zero, 1.0) << "the synthetic pair should move its parts by more than a pixel";
  EXPECT_LT(moving, 0.5 * moving_zero) << eval_json;
  EXPECT_LT(epe, epe_zero) << eval_json;
  EXPECT_LT(epe3d, epe3d_zero) << eval_json;
}

}  // namespace

TEST(Cli, HelpListsCommandsAndOptions) {
  CliRun run = runCli("--help");
  EXPECT_EQ(run.code, 0);
  for (const char* word : {"run", "synth", "eval", "demo"}) EXPECT_NE(run.out.find(word), std::string::npos) << word;
  run = runCli("run --help");
  EXPECT_EQ(run.code, 0);
  for (const char* flag : {"--rgb1", "--depth-scale", "--camera-info", "--regularizer", "--set", "--out"})
    EXPECT_NE(run.out.find(flag), std::string::npos) << flag;
}

TEST(Cli, SynthWritesInputsAndGroundTruth) {
  const fs::path& s = synthDir();
  expectImage(s / "rgb1.png", CV_8UC3, kWidth, kHeight);
  expectImage(s / "rgb2.png", CV_8UC3, kWidth, kHeight);
  expectImage(s / "depth1.png", CV_16UC1, kWidth, kHeight);
  expectImage(s / "depth2.png", CV_16UC1, kWidth, kHeight);
  expectImage(s / "gt_occlusion.png", CV_8UC1, kWidth, kHeight);
  const ImageF depth = io::readPfm((s / "depth1.pfm").string());
  EXPECT_EQ(depth.channels, 1);
  EXPECT_TRUE(depth.sameSize(kWidth, kHeight));
  // The 16-bit PNG holds the same depth in millimetres.
  const ImageF depth_mm = io::loadDepth((s / "depth1.png").string(), 1000.0);
  for (std::size_t p = 0; p < depth.pixelCount(); p += 97)
    if (isValidDepth(depth.data[p])) EXPECT_NEAR(depth_mm.data[p], depth.data[p], 0.0005 + 1e-6);
  EXPECT_TRUE(io::readFlo((s / "gt_optical_flow.flo").string()).sameSize(kWidth, kHeight));
  EXPECT_EQ(io::readPfm((s / "gt_scene_flow.pfm").string()).channels, 3);
  EXPECT_TRUE(io::loadLabels((s / "gt_parts.png").string()).sameSize(kWidth, kHeight));
  const Intrinsics K = io::parseIntrinsics(intrinsicsText());
  const io::CameraInfo info = io::loadCameraInfo((s / "camera_info.yaml").string());
  EXPECT_EQ(info.intrinsics.fx, K.fx);
  EXPECT_EQ(info.intrinsics.cy, K.cy);
  EXPECT_EQ(info.width, kWidth);
  EXPECT_TRUE(pythonJsonValid((s / "gt_segments.json").string()));
}

TEST(Cli, RunWritesEveryOutputAtInputResolution) {
  const fs::path out = workDir() / "run_png";
  const CliRun run =
      runCli("run " + inputArgs() + " --intrinsics " + intrinsicsText() + " --out " + quote(out.string()));
  ASSERT_EQ(run.code, 0) << run.err;
  EXPECT_NE(run.err.find("loading"), std::string::npos);
  EXPECT_NE(run.err.find("solving"), std::string::npos);
  EXPECT_NE(run.err.find("writing"), std::string::npos);

  const ImageF flow = io::readFlo((out / "optical_flow.flo").string());
  EXPECT_EQ(flow.channels, 2);
  EXPECT_TRUE(flow.sameSize(kWidth, kHeight));
  const ImageF scene = io::readPfm((out / "scene_flow.pfm").string());
  EXPECT_EQ(scene.channels, 3);
  EXPECT_TRUE(scene.sameSize(kWidth, kHeight));
  expectImage(out / "occlusion.png", CV_8UC1, kWidth, kHeight);
  expectImage(out / "segmentation.png", CV_8UC3, kWidth, kHeight);
  expectImage(out / "flow.png", CV_8UC3, kWidth, kHeight);
  expectImage(out / "overview.png", CV_8UC3, 3 * kWidth, 2 * kHeight);
  for (const char* json : {"segments.json", "report.json"}) EXPECT_TRUE(pythonJsonValid((out / json).string())) << json;

  // Labels agree with the soft labels' argmax, and the plane count with segments.json.
  const ImageI32 labels = io::loadLabels((out / "labels.png").string());
  ASSERT_TRUE(labels.sameSize(kWidth, kHeight));
  const SoftLabels u = io::readSoftLabelsNpy((out / "soft_labels.npy").string());
  ASSERT_TRUE(u.width == kWidth && u.height == kHeight);
  ASSERT_GE(u.count, 2);
  const std::string segments = io::readTextFile((out / "segments.json").string());
  std::size_t listed = 0;
  for (std::size_t at = segments.find("\"id\":"); at != std::string::npos; at = segments.find("\"id\":", at + 1))
    ++listed;
  EXPECT_EQ(listed, std::size_t(u.count - 1));
  std::size_t checked = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      double sum = 0;
      int best = 0;
      for (int i = 0; i < u.count; ++i) {
        sum += u.at(i, x, y);
        if (u.at(i, x, y) > u.at(best, x, y)) best = i;
      }
      EXPECT_NEAR(sum, 1.0, 1e-3);
      EXPECT_LE(labels(x, y), u.count - 1);
      if (labels(x, y) > 0) {
        ++checked;
        EXPECT_EQ(best, labels(x, y) - 1) << "at " << x << "," << y;
      }
    }
  EXPECT_GT(checked, std::size_t(kWidth * kHeight / 2));
  // NaN flow exactly where the input has no depth.
  const ImageF depth = io::readPfm((synthDir() / "depth1.pfm").string());
  for (std::size_t p = 0; p < depth.pixelCount(); ++p)
    if (!isValidDepth(depth.data[p])) EXPECT_TRUE(std::isnan(flow.data[2 * p]));

  const std::string report = io::readTextFile((out / "report.json").string());
  EXPECT_EQ(jsonNumber(report, "width"), kWidth);
  for (const char* key : {"\"lambda_quadratic\"", "\"motion\"", "\"labels_after\"", "\"final_energy\"", "\"backend\"",
                          "\"static_world\"", "\"chosen_by\""})
    EXPECT_NE(report.find(key), std::string::npos) << key;
  // The static world (the scene's room) is named alike in the summary on stdout and in segments.json.
  auto count = [](const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
  };
  EXPECT_GE(count(run.out, ", static world"), 1u) << run.out;
  EXPECT_EQ(count(run.out, ", static world"), count(segments, "\"world\": true")) << run.out << segments;
}

TEST(Cli, EvalOfExactDepthRunRecoversMotion) {
  // Float PFM depth and the camera_info YAML: the exact synthetic depth.
  expectRecoversMotion(runAndEvaluate(
      "run_pfm", inputArgs(".pfm") + " --camera-info " + quote((synthDir() / "camera_info.yaml").string())));
  // Every true part has its majority id; the static background (part 0) is mostly one segment.
  const nlohmann::json eval = io::readJsonFile((workDir() / "run_pfm" / "eval.json").string());
  std::set<int> parts;
  for (int part : io::loadLabels((synthDir() / "gt_parts.png").string()).data)
    if (part >= 0) parts.insert(part);
  ASSERT_EQ(eval.at("part_ids").size(), parts.size()) << eval.at("part_ids").dump();
  const nlohmann::json& background = eval.at("part_ids")[0];
  EXPECT_EQ(background.at("part").get<int>(), 0);
  EXPECT_GT(background.at("majority_id").get<int>(), 0);
  EXPECT_GT(background.at("share").get<double>(), 0.5) << background.dump();
}

TEST(Cli, EvalOfMillimetreDepthRunRecoversMotion) {
  // The 16-bit millimetre PNGs (0.5 mm quantisation), as a ROS 16UC1 camera would give them.
  expectRecoversMotion(runAndEvaluate("run_png_eval", inputArgs() + " --intrinsics " + intrinsicsText()));
}

TEST(Cli, EvalWithoutGroundTruthGivesResiduals) {
  const fs::path out = workDir() / "run_residuals";
  const std::string inputs = inputArgs(".pfm") + " --intrinsics " + intrinsicsText();
  ASSERT_EQ(runCli("run " + inputs + " --set outer_iterations=2 --out " + quote(out.string())).code, 0);
  const CliRun eval = runCli("eval --result " + quote(out.string()) + " " + inputs);
  ASSERT_EQ(eval.code, 0) << eval.err;
  const std::string json = io::readTextFile((out / "eval.json").string());
  EXPECT_TRUE(std::isnan(jsonNumber(json, "optical_flow_epe_px")));  // null without ground truth
  const double photometric = jsonNumber(json, "rmse_photometric");
  const double geometric = jsonNumber(json, "rmse_geometric_m");
  ASSERT_TRUE(std::isfinite(photometric) && std::isfinite(geometric)) << json;
  // Warping with the estimated motion must explain frame 2 better than assuming no motion.
  EXPECT_LT(photometric, jsonNumber(json, "rmse_photometric_zero_flow"));
  EXPECT_LT(geometric, jsonNumber(json, "rmse_geometric_zero_flow_m"));
}

TEST(Cli, ConfigFileAndFlagsReachTheReport) {
  const fs::path out = workDir() / "run_config";
  const fs::path config = workDir() / "solver.yaml";
  std::ofstream(config) << "alpha: 1.5\nouter_iterations: 1\ninitial_labels: 6\n";
  const CliRun run =
      runCli("run " + inputArgs() + " --intrinsics " + intrinsicsText() + " --config " + quote(config.string()) +
             " --labels 8 --regularizer tv --set lambda_tv=0.5 --out " + quote(out.string()));
  ASSERT_EQ(run.code, 0) << run.err;
  const std::string report = io::readTextFile((out / "report.json").string());
  EXPECT_EQ(jsonNumber(report, "alpha"), 1.5);         // from the file
  EXPECT_EQ(jsonNumber(report, "initial_labels"), 8);  // the flag overrides the file
  EXPECT_EQ(jsonNumber(report, "lambda_tv"), 0.5);     // --set
  EXPECT_EQ(jsonNumber(report, "outer_iterations"), 1);
  EXPECT_NE(report.find("\"regularizer\": \"tv\""), std::string::npos) << report;
}

// ---------------------------------------------------------------- bad inputs

namespace {

// Runs `run` with the shared pair, replacing one argument; expects failure and `needle` in stderr.
void expectRunFails(const std::string& arguments, const std::string& needle, bool case_insensitive = false) {
  const CliRun run = runCli(arguments);
  EXPECT_NE(run.code, 0) << arguments;
  const std::string err = case_insensitive ? lower(run.err) : run.err;
  EXPECT_NE(err.find(case_insensitive ? lower(needle) : needle), std::string::npos)
      << "stderr does not name '" << needle << "':\n"
      << run.err;
}

std::string outArg(const std::string& name) { return " --out " + quote((workDir() / name).string()); }

}  // namespace

TEST(CliErrors, MissingFile) {
  const std::string missing = (workDir() / "no_such_rgb.png").string();
  expectRunFails("run --rgb1 " + quote(missing) + " --depth1 " + quote((synthDir() / "depth1.png").string()) +
                     " --rgb2 " + quote((synthDir() / "rgb2.png").string()) + " --depth2 " +
                     quote((synthDir() / "depth2.png").string()) + " --intrinsics " + intrinsicsText() + outArg("e1"),
                 missing);
}

TEST(CliErrors, SizeMismatch) {
  const std::string small = (workDir() / "depth_small.png").string();
  ASSERT_TRUE(cv::imwrite(small, cv::Mat(kHeight / 2, kWidth / 2, CV_16UC1, cv::Scalar(1500))));
  expectRunFails("run --rgb1 " + quote((synthDir() / "rgb1.png").string()) + " --depth1 " + quote(small) + " --rgb2 " +
                     quote((synthDir() / "rgb2.png").string()) + " --depth2 " +
                     quote((synthDir() / "depth2.png").string()) + " --intrinsics " + intrinsicsText() + outArg("e2"),
                 small);
}

TEST(CliErrors, SecondFrameSizeMismatch) {
  const fs::path other = workDir() / "synth_other";
  ASSERT_EQ(runCli("synth --out " + quote(other.string()) + " --width 80 --height 60").code, 0);
  const std::string rgb2 = (other / "rgb2.png").string();
  expectRunFails("run --rgb1 " + quote((synthDir() / "rgb1.png").string()) + " --depth1 " +
                     quote((synthDir() / "depth1.png").string()) + " --rgb2 " + quote(rgb2) + " --depth2 " +
                     quote((other / "depth2.png").string()) + " --intrinsics " + intrinsicsText() + outArg("e2b"),
                 rgb2);
}

TEST(CliErrors, EightBitDepth) {
  const std::string eight = (workDir() / "depth8.png").string();
  ASSERT_TRUE(cv::imwrite(eight, cv::Mat(kHeight, kWidth, CV_8UC1, cv::Scalar(100))));
  const std::string args = "run --rgb1 " + quote((synthDir() / "rgb1.png").string()) + " --depth1 " + quote(eight) +
                           " --rgb2 " + quote((synthDir() / "rgb2.png").string()) + " --depth2 " +
                           quote((synthDir() / "depth2.png").string()) + " --intrinsics " + intrinsicsText() +
                           outArg("e3");
  expectRunFails(args, eight);
  expectRunFails(args, "16-bit");
}

TEST(CliErrors, AllZeroDepth) {
  const std::string zero = (workDir() / "depth_zero.png").string();
  ASSERT_TRUE(cv::imwrite(zero, cv::Mat(kHeight, kWidth, CV_16UC1, cv::Scalar(0))));
  expectRunFails("run --rgb1 " + quote((synthDir() / "rgb1.png").string()) + " --depth1 " +
                     quote((synthDir() / "depth1.png").string()) + " --rgb2 " +
                     quote((synthDir() / "rgb2.png").string()) + " --depth2 " + quote(zero) + " --intrinsics " +
                     intrinsicsText() + outArg("e4"),
                 zero);
}

TEST(CliErrors, ZeroIntrinsics) {
  expectRunFails("run " + inputArgs() + " --intrinsics 0,0,80,60" + outArg("e5"), "fx");
}

TEST(CliErrors, MalformedIntrinsics) {
  expectRunFails("run " + inputArgs() + " --intrinsics 120,120,eighty" + outArg("e6"), "120,120,eighty");
}

TEST(CliErrors, MissingCameraInfoFile) {
  const std::string missing = (workDir() / "no_camera_info.yaml").string();
  expectRunFails("run " + inputArgs() + " --camera-info " + quote(missing) + outArg("e6b"), missing);
}

TEST(CliErrors, BadRegularizer) {
  expectRunFails("run " + inputArgs() + " --intrinsics " + intrinsicsText() + " --regularizer huber" + outArg("e7"),
                 "huber");
}

TEST(CliErrors, BadConfigValues) {
  const std::string base = "run " + inputArgs() + " --intrinsics " + intrinsicsText();
  expectRunFails(base + " --set alpha=-1" + outArg("e8"), "alpha");
  expectRunFails(base + " --set no_such_field=3" + outArg("e8"), "no_such_field");
  expectRunFails(base + " --labels 0" + outArg("e8"), "initial_labels");
  const fs::path config = workDir() / "bad.json";
  std::ofstream(config) << "{\"lambda_quadratic\": -2}";
  expectRunFails(base + " --config " + quote(config.string()) + outArg("e8"), "lambda_quadratic");
  expectRunFails(base + " --config " + quote((workDir() / "missing.json").string()) + outArg("e8"), "missing.json");
}

TEST(CliErrors, UnknownFlagAndCommand) {
  CliRun run = runCli("run " + inputArgs() + " --intrinsics " + intrinsicsText() + " --bogus 1" + outArg("e9"));
  EXPECT_EQ(run.code, 2);
  EXPECT_NE(run.err.find("--bogus"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("usage"), std::string::npos) << run.err;
  run = runCli("frobnicate");
  EXPECT_EQ(run.code, 2);
  EXPECT_NE(run.err.find("frobnicate"), std::string::npos) << run.err;
  run = runCli("run " + inputArgs() + " --intrinsics " + intrinsicsText());  // no --out
  EXPECT_EQ(run.code, 2);
  EXPECT_NE(run.err.find("--out"), std::string::npos) << run.err;
}

// Every subcommand parses with the one CommandLine: a usage error exits 2 naming the option (and the value), and
// prints the subcommand's usage; --help and -h print it to stdout.
TEST(CliErrors, EverySubcommandNamesTheOptionAndValueAndExits2) {
  const std::string out = outArg("e_usage");
  struct Case {
    std::string arguments;
    std::vector<std::string> needles;
  };
  const std::vector<Case> cases = {
      {"synth" + out + " --width abc", {"--width", "'abc'"}},
      {"synth" + out + " --variant 99", {"--variant", "'99'"}},
      {"synth" + out + " --set alpha=1", {"unknown option", "--set"}},
      {"synth" + out + " --noise=yes", {"--noise", "takes no value"}},
      {"synth" + out + " --out", {"--out", "needs a value"}},
      {"demo" + out + " --width 64 --width 80", {"--width", "given twice"}},
      {"run " + inputArgs() + " --intrinsics " + intrinsicsText() + out + " --set alpha", {"--set", "'alpha'"}},
      {"run " + inputArgs() + " --intrinsics " + intrinsicsText() + out + " --max-depth far", {"--max-depth", "far"}},
      {"run-seq --tum " + quote(workDir().string()) + out + " --fps x", {"--fps", "'x'"}},
      {"eval-traj --gt a --est b --offset 1s", {"--offset", "'1s'"}},
      {"bench-real --data d --repeat 0", {"--repeat", "'0'"}},
      {"bench-real --data d --mask none", {"--mask", "'none'"}},
      {"export-real --data d --out o --pairs ,", {"--pairs", "names no pair"}},
      {"export-seq --out o", {"--tum", "--frames"}},
      {"eval stray", {"unexpected argument", "stray"}},
  };
  for (const Case& c : cases) {
    const CliRun run = runCli(c.arguments);
    EXPECT_EQ(run.code, 2) << c.arguments << "\n" << run.err;
    for (const std::string& needle : c.needles) EXPECT_NE(run.err.find(needle), std::string::npos) << run.err;
    EXPECT_NE(run.err.find("usage: mcflow"), std::string::npos) << run.err;
  }
  for (const char* command :
       {"run", "run-seq", "synth", "eval", "demo", "bench-real", "eval-traj", "export-real", "export-seq"})
    for (const char* help : {"--help", "-h"}) {
      const CliRun run = runCli(std::string(command) + " " + help);
      EXPECT_EQ(run.code, 0) << command << " " << help << ": " << run.err;
      EXPECT_EQ(run.out.rfind(std::string("usage: mcflow ") + command, 0), 0u) << run.out;
      EXPECT_NE(run.out.find("--help"), std::string::npos) << run.out;
    }
}

TEST(CliErrors, UnwritableOutputDirectory) {
  const fs::path file = workDir() / "a_regular_file";
  std::ofstream(file) << "x";
  const std::string out = (file / "sub").string();
  expectRunFails("run " + inputArgs() + " --intrinsics " + intrinsicsText() + " --out " + quote(out), out);
}

TEST(CliErrors, CudaBackendWithoutGpu) {
  const CliRun run =
      runCli("run " + inputArgs() + " --intrinsics " + intrinsicsText() + " --backend cuda" + outArg("e10"));
  if (run.code == 0) GTEST_SKIP() << "a usable CUDA backend is present here, so forcing it succeeds";
  EXPECT_EQ(run.code, 2);
  EXPECT_NE(lower(run.err).find("cuda"), std::string::npos) << run.err;
}

// A pair that would not fit in memory is refused after loading, before the solve, naming the estimate and
// what is available. MCFLOW_MEMINFO stands in for /proc/meminfo, so no large image is needed.
TEST(CliErrors, PairLargerThanAvailableMemoryIsRefusedNamingTheEstimate) {
  const fs::path meminfo = workDir() / "meminfo";
  io::writeTextFile(meminfo.string(), "MemTotal:        2048 kB\nMemAvailable:    1024 kB\n");
  ::setenv("MCFLOW_MEMINFO", meminfo.c_str(), 1);
  const CliRun run = runCli("run " + inputArgs() + " --intrinsics " + intrinsicsText() + outArg("e_memory"));
  ::unsetenv("MCFLOW_MEMINFO");
  EXPECT_EQ(run.code, 1) << run.err;
  EXPECT_NE(run.err.find("a 160x120 pair at processing level 0 (160x120) needs about"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("only 1 MB is available (MemAvailable in /proc/meminfo)"), std::string::npos) << run.err;
  EXPECT_FALSE(fs::exists(workDir() / "e_memory" / "optical_flow.flo"));
}

// ---------------------------------------------------------------- sequences

TEST(Cli, SynthSequenceThenRunSeqKeepsIdsAndWritesTheSequenceFiles) {
  const fs::path seq = workDir() / "sequence", out = workDir() / "sequence_out";
  const CliRun synth = runCli("synth --out " + quote(seq.string()) + " --frames 4 --width 96 --height 72");
  ASSERT_EQ(synth.code, 0) << synth.err;
  for (const char* f : {"rgb.txt", "depth.txt", "camera_info.yaml", "rgb/0003.png", "depth/0003.png",
                        "gt/pair_0002/gt_optical_flow.flo"})
    EXPECT_TRUE(fs::exists(seq / f)) << f;
  EXPECT_FALSE(fs::exists(seq / "gt/pair_0003")) << "4 frames make 3 pairs";

  const CliRun run = runCli("run-seq --tum " + quote(seq.string()) + " --out " + quote(out.string()));
  ASSERT_EQ(run.code, 0) << run.err;
  EXPECT_NE(run.out.find("3 pair(s) solved"), std::string::npos) << run.out;
  for (const char* f : {"pair_0000/labels.png", "pair_0002/segments.json", "pair_0002/moving.png", "trajectories.csv",
                        "sequence.json", "ids_over_time.png", "trajectory.txt", "odometry.csv"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  EXPECT_TRUE(pythonJsonValid((out / "sequence.json").string()));
  const std::string csv = io::readTextFile((out / "trajectories.csv").string());
  EXPECT_EQ(csv.rfind("pair,stamp,id,vx,vy,vz,wx,wy,wz,support,world,moving,", 0), 0u) << csv.substr(0, 80);
  // The camera's path: the first frame at the identity, one pose per frame; scored against itself it has no error.
  const auto path = io::readTumTrajectory((out / "trajectory.txt").string());
  ASSERT_EQ(path.size(), 4u);
  EXPECT_TRUE(path[0].second.isIdentity());
  const CliRun self =
      runCli("eval-traj --gt " + quote((out / "trajectory.txt").string()) + " --est " +
             quote((out / "trajectory.txt").string()) + " --plot " + quote((workDir() / "traj.png").string()));
  ASSERT_EQ(self.code, 0) << self.err;
  EXPECT_NE(self.out.find("ate_rmse_m 0.0000"), std::string::npos) << self.out;
  EXPECT_TRUE(fs::exists(workDir() / "traj.png"));
  // Each pair's camera motion with its covariance; scored against the path it integrates to, its NEES is about 0 (the
  // path's 6 decimals against a covariance of at least the floor's).
  EXPECT_EQ(io::readOdometryCsv((out / "odometry.csv").string()).size(), 3u);
  const CliRun consistency =
      runCli("eval-traj --gt " + quote((out / "trajectory.txt").string()) + " --est " +
             quote((out / "trajectory.txt").string()) + " --odometry " + quote((out / "odometry.csv").string()));
  ASSERT_EQ(consistency.code, 0) << consistency.err;
  EXPECT_NE(consistency.out.find("3 of 3 steps matched (the trajectory has 3 consecutive pairs)"), std::string::npos)
      << consistency.out;
  EXPECT_NE(consistency.out.find("nees_median 0.00"), std::string::npos) << consistency.out;
  const CliRun no_match = runCli("eval-traj --gt " + quote((out / "trajectory.txt").string()) + " --est " +
                                 quote((out / "trajectory.txt").string()) + " --offset 100");
  EXPECT_EQ(no_match.code, 1) << no_match.out;
  EXPECT_NE(no_match.err.find("0 of 4"), std::string::npos) << no_match.err;
  const std::string log = io::readTextFile((out / "sequence.json").string());
  EXPECT_NE(log.find("\"start\": \"warm\""), std::string::npos) << log;
  // The background keeps its id: the same id covers the most pixels in the first and the last pair.
  auto mostCommon = [](const ImageI32& labels) {
    std::map<int, int> count;
    for (int id : labels.data)
      if (id > 0) ++count[id];
    int best = 0, n = 0;
    for (const auto& [id, c] : count)
      if (c > n) best = id, n = c;
    return best;
  };
  EXPECT_EQ(mostCommon(io::loadLabels((out / "pair_0000/labels.png").string())),
            mostCommon(io::loadLabels((out / "pair_0002/labels.png").string())));

  // --cold solves every pair from K-means; usage errors name the problem.
  const CliRun cold = runCli("run-seq --tum " + quote(seq.string()) + " --cold --max-frames 2 --out " +
                             quote((workDir() / "cold_out").string()));
  ASSERT_EQ(cold.code, 0) << cold.err;
  EXPECT_NE(cold.out.find("1 pair(s) solved (0 warm"), std::string::npos) << cold.out;
  const CliRun both = runCli("run-seq --tum a --frames b --out " + quote((workDir() / "x").string()));
  EXPECT_EQ(both.code, 2);
  EXPECT_NE(both.err.find("one of --tum DIR, --frames DIR or --bag FILE"), std::string::npos) << both.err;
  const CliRun missing = runCli("run-seq --tum " + quote((workDir() / "nothing").string()) + " --out " +
                                quote((workDir() / "y").string()));
  EXPECT_EQ(missing.code, 1);
  EXPECT_NE(missing.err.find("not a directory"), std::string::npos) << missing.err;
}

// run-seq with a CUDA backend that cannot be made (no GPU here; a cuda_device that does not exist on a GPU machine)
// solves on the CPU rather than not at all, and says why (`mcflow run` stops instead: CudaBackendWithoutGpu).
TEST(Cli, RunSeqOnAnUnusableCudaBackendRunsOnTheCpuAndSaysWhy) {
  const fs::path seq = workDir() / "sequence_cuda", out = workDir() / "sequence_cuda_out";
  const CliRun synth = runCli("synth --out " + quote(seq.string()) + " --frames 2 --width 96 --height 72");
  ASSERT_EQ(synth.code, 0) << synth.err;
  const CliRun run = runCli("run-seq --tum " + quote(seq.string()) + " --backend cuda --set cuda_device=63 --out " +
                            quote(out.string()));
  ASSERT_EQ(run.code, 0) << run.err;
  EXPECT_NE(run.out.find("1 pair(s) solved"), std::string::npos) << run.out;
  EXPECT_NE(run.err.find("warning: backend 'cuda' cannot be used: running on the CPU (CUDA backend requested but "
                         "unavailable: "),
            std::string::npos)
      << run.err;
}

// --no-events leaves out the sequence's two extra boxes (parts 10 and 11): the demo bag's scene.
TEST(Cli, SynthSequenceWithoutEventsHasOnlyTheSceneParts) {
  auto partsOf = [](const fs::path& dir) {
    std::set<int> parts;
    for (int part : io::loadLabels((dir / "gt/pair_0000/gt_parts.png").string()).data) parts.insert(part);
    return parts;
  };
  const fs::path with = workDir() / "events", without = workDir() / "no_events";
  ASSERT_EQ(runCli("synth --out " + quote(with.string()) + " --frames 2 --width 96 --height 72").code, 0);
  const CliRun run =
      runCli("synth --out " + quote(without.string()) + " --frames 2 --width 96 --height 72 --no-events");
  ASSERT_EQ(run.code, 0) << run.err;
  EXPECT_TRUE(partsOf(with).count(10)) << "the late box is in view at frame 0";
  const std::set<int> parts = partsOf(without);
  EXPECT_FALSE(parts.count(10) || parts.count(11));
  EXPECT_GE(parts.size(), 3u);
  EXPECT_EQ(runCli("synth --out " + quote((workDir() / "pair_events").string()) + " --no-events").code, 2);
}

// --bag reads rosbags only where the tool was built with ROS (test/ros/test_bag_sequence.cpp runs it); elsewhere
// the option is known and refused, naming the missing build.
TEST(CliErrors, RunSeqBagNamesTheRosBuildOrTheMissingFile) {
  const CliRun run = runCli("run-seq --bag " + quote((workDir() / "absent.bag").string()) + " --out " +
                            quote((workDir() / "bag_out").string()));
#ifdef MCFLOW_CLI_HAS_BAG
  EXPECT_EQ(run.code, 1) << run.err;
  EXPECT_NE(run.err.find("absent.bag': does not exist"), std::string::npos) << run.err;
#else
  EXPECT_EQ(run.code, 2) << run.err;
  EXPECT_NE(run.err.find("--bag needs the ROS build"), std::string::npos) << run.err;
#endif
  EXPECT_FALSE(fs::exists(workDir() / "bag_out"));
}
