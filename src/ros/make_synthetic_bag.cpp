/**
 * @file make_synthetic_bag.cpp
 * @brief Writes a rosbag of the project's synthetic RGB-D sequence (moving boxes and an articulated arm in
 * a textured room), with the topics of an OpenNI-style camera: the demo's input, no camera needed.
 *
 * Usage: make_synthetic_bag OUTPUT.bag [--frames N] [--rate HZ] [--width W] [--height H] [--variant V]
 *        [--namespace /camera] [--frame-id camera_rgb_optical_frame] [--depth-encoding 32FC1|16UC1]
 *        [--depth-noise M] [--intensity-noise I]
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

#include "mc_flow/eval/synthetic_scene.h"

namespace {

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

void usage() {
  std::cerr << "usage: make_synthetic_bag OUTPUT.bag [--frames N (20)] [--rate HZ (10)] [--width W (640)]\n"
               "       [--height H (480)] [--variant V (0)] [--namespace NS (/camera)]\n"
               "       [--frame-id ID (camera_rgb_optical_frame)] [--base-frame ID (camera_link)]\n"
               "       [--depth-encoding 32FC1|16UC1] [--depth-frame-id ID (the colour one)] [--no-tf]\n"
               "       [--depth-noise M (0)] [--intensity-noise I (0)]\n";
}

bool parse(int argc, char** argv, Options& o) {
  o.scene.width = 640;
  o.scene.height = 480;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error("missing value after " + arg);
      return argv[++i];
    };
    if (arg == "--frames")
      o.frames = std::stoi(next());
    else if (arg == "--rate")
      o.rate = std::stod(next());
    else if (arg == "--width")
      o.scene.width = std::stoi(next());
    else if (arg == "--height")
      o.scene.height = std::stoi(next());
    else if (arg == "--variant")
      o.scene.variant = std::stoi(next());
    else if (arg == "--namespace")
      o.ns = next();
    else if (arg == "--frame-id")
      o.frame_id = next();
    else if (arg == "--base-frame")
      o.base_frame = next();
    else if (arg == "--depth-encoding")
      o.depth_encoding = next();
    else if (arg == "--depth-frame-id")
      o.depth_frame_id = next();
    else if (arg == "--no-tf")
      o.write_tf = false;
    else if (arg == "--depth-noise")
      o.scene.depth_noise = std::stod(next());
    else if (arg == "--intensity-noise")
      o.scene.intensity_noise = std::stod(next());
    else if (arg == "-h" || arg == "--help")
      return false;
    else if (!arg.empty() && arg[0] == '-')
      throw std::runtime_error("unknown option " + arg);
    else
      o.output = arg;
  }
  if (o.output.empty()) throw std::runtime_error("no output file given");
  if (o.frames < 2) throw std::runtime_error("--frames " + std::to_string(o.frames) + ": need at least 2");
  if (!(o.rate > 0)) throw std::runtime_error("--rate must be > 0");
  if (o.depth_encoding != "32FC1" && o.depth_encoding != "16UC1") {
    throw std::runtime_error("--depth-encoding " + o.depth_encoding + ": use 32FC1 or 16UC1");
  }
  while (!o.ns.empty() && o.ns.back() == '/') o.ns.pop_back();
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  try {
    if (!parse(argc, argv, o)) {
      usage();
      return 0;
    }
  } catch (const std::exception& e) {
    std::cerr << "make_synthetic_bag: " << e.what() << "\n";
    usage();
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
