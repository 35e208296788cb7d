// Seed corpus for the fuzz targets, one folder per target, from a small pair written by `mcflow synth`:
//   fuzz_make_seeds SYNTH_DIR OUT_DIR
// Each loader gets every format it accepts (colour: 8/16-bit PNG, PGM, TIFF, BGRA; depth: 16-bit PNG and
// PGM, float TIFF and EXR; PFM of 1 and 3 channels; .flo; camera_info; config in YAML and JSON), so that
// mutation starts from valid files of each format. A format this OpenCV cannot write is skipped and named.
#include <cstdio>
#include <filesystem>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "mc_flow/core/config.h"
#include "mc_flow/io/flow_io.h"
#include "mc_flow/io/image_io.h"
#include "mc_flow/io/report_io.h"

namespace fs = std::filesystem;
using namespace mc_flow;

namespace {

void write(const fs::path& path, const cv::Mat& image) {
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), image);
  } catch (const cv::Exception&) {
  }
  if (!ok) std::fprintf(stderr, "fuzz_make_seeds: this OpenCV cannot write %s; seed skipped\n", path.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: fuzz_make_seeds SYNTH_DIR OUT_DIR\n");
    return 2;
  }
  const fs::path synth = argv[1], out = argv[2];
  for (const char* target : {"colour_image", "depth_image", "depth_pfm", "flo", "camera_info", "config_file"})
    fs::create_directories(out / target);

  const cv::Mat bgr = cv::imread((synth / "rgb1.png").string(), cv::IMREAD_COLOR);
  cv::Mat grey, bgra, bgr16;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
  bgr.convertTo(bgr16, CV_16UC3, 257.0);
  write(out / "colour_image" / "bgr8.png", bgr);
  write(out / "colour_image" / "bgra8.png", bgra);
  write(out / "colour_image" / "bgr16.png", bgr16);
  write(out / "colour_image" / "grey8.pgm", grey);
  write(out / "colour_image" / "bgr8.tiff", bgr);

  const cv::Mat depth_mm = cv::imread((synth / "depth1.png").string(), cv::IMREAD_ANYDEPTH);
  const ImageF depth_m = io::readPfm((synth / "depth1.pfm").string());
  write(out / "depth_image" / "depth16.png", depth_mm);
  write(out / "depth_image" / "depth16.pgm", depth_mm);
  write(out / "depth_image" / "depth32f.tiff", io::toMat(depth_m));
  write(out / "depth_image" / "depth32f.exr", io::toMat(depth_m));

  io::writePfm((out / "depth_pfm" / "depth.pfm").string(), depth_m);
  io::writePfm((out / "depth_pfm" / "scene_flow.pfm").string(), io::readPfm((synth / "gt_scene_flow.pfm").string()));
  io::writeFlo((out / "flo" / "flow.flo").string(), io::readFlo((synth / "gt_optical_flow.flo").string()));
  fs::copy_file(synth / "camera_info.yaml", out / "camera_info" / "camera_info.yaml",
                fs::copy_options::overwrite_existing);

  std::string yaml, json = "{";
  for (const auto& [name, value] : Config().fields()) {
    yaml += name + ": " + value + "\n";
    json += std::string(json.size() > 1 ? ", " : "") + "\"" + name + "\": \"" + value + "\"";
  }
  io::writeTextFile((out / "config_file" / "config.yaml").string(), yaml);
  io::writeTextFile((out / "config_file" / "config.json").string(), json + "}\n");
  return 0;
}
