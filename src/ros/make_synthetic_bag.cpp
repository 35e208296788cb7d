/**
 * @file make_synthetic_bag.cpp
 * @brief Writes a rosbag of the project's synthetic RGB-D sequence (moving boxes and an articulated arm in
 * a textured room), with the topics of an OpenNI-style camera: the demo's input, no camera needed.
 *
 * Usage: make_synthetic_bag OUTPUT.bag [--frames N] [--rate HZ] [--width W] [--height H] [--variant V]
 *        [--namespace /camera] [--frame-id camera_rgb_optical_frame] [--depth-encoding 32FC1|16UC1]
 *        [--depth-noise M] [--intensity-noise I] (make_synthetic_bag --help lists every option)
 */
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>

#include <rosbag/bag.h>
#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_msgs/TFMessage.h>

#include "mc_flow/cli/command_line.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace {

using mc_flow::CommandLine;
using mc_flow::CommandLineError;
using mc_flow::ConfigSettings;

struct Options {
  std::string output;
  int frames = 20;
  double rate = 10.0;  // [Hz]
  std::string ns = "/camera";
  std::string frame_id = "camera_rgb_optical_frame";
  std::string base_frame = "camera_link";
  std::string depth_encoding = "32FC1";
  std::string depth_frame_id;  // empty: the colour frame_id
  bool write_tf = true;        // false: only the three camera topics, as many recorded bags
  mc_flow::SyntheticSceneOptions scene;
};

CommandLine commandLine() {
  return CommandLine("make_synthetic_bag",
                     {{"frames", true, "number of frames, at least 2 (default 20)"},
                      {"rate", true, "frame rate [Hz] (default 10)"},
                      {"width", true, "image width (default 640)"},
                      {"height", true, "image height (default 480)"},
                      {"variant", true, "scene variant (default 0)"},
                      {"namespace", true, "topic namespace (default /camera)"},
                      {"frame-id", true, "colour optical frame (default camera_rgb_optical_frame)"},
                      {"base-frame", true, "body frame of /tf_static (default camera_link)"},
                      {"depth-encoding", true, "32FC1 (metres, default) | 16UC1 (millimetres)"},
                      {"depth-frame-id", true, "frame of the depth images (default: the colour one)"},
                      {"no-tf", false, "no /tf_static: only the three camera topics, as many recorded bags"},
                      {"depth-noise", true, "[m] depth noise at 1 m (default 0)"},
                      {"intensity-noise", true, "intensity noise, intensity in [0, 1] (default 0)"}},
                     ConfigSettings::Refused, {"OUTPUT.bag"});
}

Options parse(const CommandLine& cli) {
  Options o;
  o.output = cli.positionalText(0, "");
  if (o.output.empty()) throw CommandLineError("no output file given");
  o.frames = cli.integer("frames", o.frames, 2, 1000000);
  o.rate = cli.number("rate", o.rate);
  if (!(o.rate > 0)) throw CommandLineError("--rate '" + cli.text("rate", "") + "': must be > 0");
  o.scene.width = cli.integer("width", 640, 1, 100000);
  o.scene.height = cli.integer("height", 480, 1, 100000);
  o.scene.variant = cli.integer("variant", o.scene.variant, 0, mc_flow::syntheticVariantCount() - 1);
  o.ns = cli.text("namespace", o.ns);
  o.frame_id = cli.text("frame-id", o.frame_id);
  o.base_frame = cli.text("base-frame", o.base_frame);
  o.depth_encoding = cli.text("depth-encoding", o.depth_encoding);
  if (o.depth_encoding != "32FC1" && o.depth_encoding != "16UC1")
    throw CommandLineError("--depth-encoding '" + o.depth_encoding + "': use 32FC1 or 16UC1");
  o.depth_frame_id = cli.text("depth-frame-id", o.depth_frame_id);
  o.write_tf = !cli.has("no-tf");
  o.scene.depth_noise = cli.number("depth-noise", o.scene.depth_noise);
  o.scene.intensity_noise = cli.number("intensity-noise", o.scene.intensity_noise);
  while (!o.ns.empty() && o.ns.back() == '/') o.ns.pop_back();
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  CommandLine cli = commandLine();
  Options o;
  try {
    cli.parse(argc, argv);
    if (cli.helpRequested()) {
      std::cout << cli.usage();
      return 0;
    }
    o = parse(cli);
  } catch (const CommandLineError& e) {
    std::cerr << "make_synthetic_bag: " << e.what() << "\n" << cli.usage();
    return 2;
  }
  ros::Time::init();
  try {
    rosbag::Bag bag(o.output, rosbag::bagmode::Write);
    const ros::Time start(1000.0);  // fixed start: the bag is the same on every run
    if (o.write_tf) {
      // Like a camera driver: a latched /tf_static from the body frame (x forward, z up) to the optical
      // frame (z forward, y down, REP 103), so viewers can use an upright fixed frame.
      tf2_msgs::TFMessage tf;
      geometry_msgs::TransformStamped t;
      t.header.stamp = start;
      t.header.frame_id = o.base_frame;
      t.child_frame_id = o.frame_id;
      t.transform.rotation.x = -0.5;
      t.transform.rotation.y = 0.5;
      t.transform.rotation.z = -0.5;
      t.transform.rotation.w = 0.5;
      tf.transforms.push_back(t);
      auto header = boost::make_shared<ros::M_string>();
      (*header)["latching"] = "1";
      (*header)["callerid"] = "/make_synthetic_bag";
      (*header)["topic"] = "/tf_static";
      (*header)["type"] = ros::message_traits::datatype<tf2_msgs::TFMessage>();
      (*header)["md5sum"] = ros::message_traits::md5sum<tf2_msgs::TFMessage>();
      (*header)["message_definition"] = ros::message_traits::definition<tf2_msgs::TFMessage>();
      bag.write("/tf_static", start, tf, header);
    }
    for (int t = 0; t < o.frames; ++t) {
      mc_flow::RgbdFrame frame;
      mc_flow::ImageU8 colour;
      mc_flow::Intrinsics K;
      mc_flow::renderSyntheticFrame(o.scene, t, frame, colour, K);
      const ros::Time stamp = start + ros::Duration(t / o.rate);
      const int w = frame.width(), h = frame.height();

      sensor_msgs::Image rgb;
      rgb.header.stamp = stamp;
      rgb.header.frame_id = o.frame_id;
      rgb.header.seq = std::uint32_t(t);
      rgb.width = std::uint32_t(w);
      rgb.height = std::uint32_t(h);
      rgb.encoding = sensor_msgs::image_encodings::RGB8;
      rgb.step = std::uint32_t(3 * w);
      rgb.data.assign(colour.data.begin(), colour.data.end());

      sensor_msgs::Image depth;
      depth.header = rgb.header;
      if (!o.depth_frame_id.empty()) depth.header.frame_id = o.depth_frame_id;
      depth.width = rgb.width;
      depth.height = rgb.height;
      depth.encoding = o.depth_encoding;
      if (o.depth_encoding == "32FC1") {
        depth.step = std::uint32_t(4 * w);
        depth.data.resize(std::size_t(depth.step) * std::size_t(h));
        for (std::size_t i = 0; i < frame.depth.data.size(); ++i) {
          const float z = mc_flow::isValidDepth(frame.depth.data[i]) ? frame.depth.data[i] : std::nanf("");
          std::memcpy(&depth.data[4 * i], &z, 4);
        }
      } else {
        depth.step = std::uint32_t(2 * w);
        depth.data.resize(std::size_t(depth.step) * std::size_t(h));
        for (std::size_t i = 0; i < frame.depth.data.size(); ++i) {
          const float z = frame.depth.data[i];
          const std::uint16_t mm =
              mc_flow::isValidDepth(z) ? std::uint16_t(std::lround(std::min(z * 1000.f, 65535.f))) : 0;
          std::memcpy(&depth.data[2 * i], &mm, 2);
        }
      }

      sensor_msgs::CameraInfo info;
      info.header = rgb.header;
      info.width = rgb.width;
      info.height = rgb.height;
      info.distortion_model = "plumb_bob";
      info.D.assign(5, 0.0);
      info.K = {K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1};
      info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
      info.P = {K.fx, 0, K.cx, 0, 0, K.fy, K.cy, 0, 0, 0, 1, 0};

      bag.write(o.ns + "/rgb/image_rect_color", stamp, rgb);
      bag.write(o.ns + "/depth_registered/image_rect", stamp, depth);
      bag.write(o.ns + "/rgb/camera_info", stamp, info);
      std::cout << "\rframe " << (t + 1) << "/" << o.frames << std::flush;
    }
    bag.close();
    std::cout << "\nwrote " << o.output << ": " << o.frames << " frames " << o.scene.width << "x" << o.scene.height
              << " at " << o.rate << " Hz, variant " << o.scene.variant << ", topics " << o.ns
              << "/{rgb/image_rect_color, depth_registered/image_rect, rgb/camera_info}\n";
  } catch (const std::exception& e) {
    std::cerr << "\nmake_synthetic_bag: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
