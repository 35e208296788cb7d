/**
 * @file mcflow_bench_nodelet.cpp
 * @brief Issue 6: the nodelet's own work per pair, around the solver, without a ROS master. Times the functions
 * the nodelet calls (conversions.h, message_validation.h) on a synthetic 640x480 pair: the validation and
 * conversion of one rgb8 image + 16UC1 depth + CameraInfo (one new frame per pair), the StreamFrame the nodelet
 * hands to the pipeline, and every output message of one pair built from a real Result of the core solver (all
 * outputs subscribed, ~publish_tf on). Optionally the ros::serialization of the outputs (what roscpp does once
 * per publish when a subscriber is in another process) and of the inputs. Numbers: docs/PERFORMANCE.md,
 * "Nodelet overhead per pair".
 *
 * usage: mcflow_bench_nodelet [--repetitions N (50)] [--downsample LIST (0,1)] [--size WxH (640x480)]
 *                             [--variant V (0)] [--depth-noise M (0)] [--real DIR] [--set name=value ...]
 * --real DIR: a pair of shared/data/real_pairs (colour0/1.png, depth0/1.png in 1/5000 m, 640x480) instead of the
 * synthetic scene; its depth is published as 16UC1 millimetres, as a driver would.
 */
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <ros/serialization.h>
#include <sys/resource.h>
#include <sensor_msgs/image_encodings.h>

#include "mc_flow/core/error.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/io/benchmark.h"
#include "mc_flow/ros/conversions.h"
#include "mc_flow/ros/message_validation.h"
#include "mc_flow/ros/node_parameters.h"
#include "mc_flow/ros/output_publishers.h"
#include "mc_flow/testing/bench.h"
#include "mc_flow/eval/synthetic_scene.h"

namespace {

using Clock = std::chrono::steady_clock;

struct InputMessages {
  sensor_msgs::Image rgb, depth;
  sensor_msgs::CameraInfo info;
};

// What a camera driver publishes: rgb8 (`colour`, RGB), 16UC1 [mm] (`depth` [m], invalid <= 0 or NaN), a
// rectified CameraInfo.
InputMessages toMessages(const mc_flow::ImageU8& colour, const mc_flow::ImageF& depth, const mc_flow::Intrinsics& K,
                         const ros::Time& stamp) {
  const int w = depth.width, h = depth.height;
  InputMessages m;
  m.rgb.header.stamp = stamp;
  m.rgb.header.frame_id = "camera_rgb_optical_frame";
  m.rgb.width = std::uint32_t(w);
  m.rgb.height = std::uint32_t(h);
  m.rgb.encoding = sensor_msgs::image_encodings::RGB8;
  m.rgb.step = std::uint32_t(3 * w);
  m.rgb.data.assign(colour.data.begin(), colour.data.end());
  m.depth.header = m.rgb.header;
  m.depth.width = m.rgb.width;
  m.depth.height = m.rgb.height;
  m.depth.encoding = sensor_msgs::image_encodings::TYPE_16UC1;
  m.depth.step = std::uint32_t(2 * w);
  m.depth.data.resize(std::size_t(m.depth.step) * std::size_t(h));
  for (std::size_t i = 0; i < depth.data.size(); ++i) {
    const float z = depth.data[i];
    const std::uint16_t mm = mc_flow::isValidDepth(z) ? std::uint16_t(std::lround(std::min(z * 1000.f, 65535.f))) : 0;
    std::memcpy(&m.depth.data[2 * i], &mm, 2);
  }
  m.info.header = m.rgb.header;
  m.info.width = m.rgb.width;
  m.info.height = m.rgb.height;
  m.info.distortion_model = "plumb_bob";
  m.info.D.assign(5, 0.0);
  m.info.K = {K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1};
  m.info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  m.info.P = {K.fx, 0, K.cx, 0, 0, K.fy, K.cy, 0, 0, 0, 1, 0};
  return m;
}

// Frame t of the synthetic scene.
InputMessages renderMessages(const mc_flow::SyntheticSceneOptions& scene, int t, const ros::Time& stamp) {
  mc_flow::RgbdFrame frame;
  mc_flow::ImageU8 colour;
  mc_flow::Intrinsics K;
  mc_flow::renderSyntheticFrame(scene, t, frame, colour, K);
  return toMessages(colour, frame.depth, K, stamp);
}

// Frame t (0 or 1) of a real pair folder (README of shared/data/real_pairs: 640x480, depth in 1/5000 m).
InputMessages realMessages(const std::string& dir, int t, const ros::Time& stamp) {
  const std::string n = std::to_string(t);
  const cv::Mat bgr = cv::imread(dir + "/color" + n + ".png", cv::IMREAD_COLOR);
  const cv::Mat raw = cv::imread(dir + "/depth" + n + ".png", cv::IMREAD_UNCHANGED);
  if (bgr.empty() || raw.empty() || raw.type() != CV_16UC1 || raw.size() != bgr.size())
    throw std::runtime_error("cannot read " + dir + "/color" + n + ".png and a 16-bit depth" + n + ".png of its size");
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  mc_flow::ImageU8 colour(rgb.cols, rgb.rows, 3);
  for (int y = 0; y < rgb.rows; ++y) std::memcpy(&colour(0, y), rgb.ptr(y), std::size_t(rgb.cols) * 3);
  mc_flow::ImageF depth(raw.cols, raw.rows, 1);
  for (int y = 0; y < raw.rows; ++y)
    for (int x = 0; x < raw.cols; ++x) depth(x, y) = float(raw.at<std::uint16_t>(y, x) / 5000.0);
  std::string name = dir;
  while (!name.empty() && name.back() == '/') name.pop_back();
  name = name.substr(name.find_last_of('/') + 1);
  return toMessages(colour, depth, mc_flow::realPairIntrinsics640(name), stamp);
}

// Minor page faults of the process so far: a fresh allocation of a few MB (a message's buffer) costs a fault per
// 4 KiB page on first touch, which on this VM is much of the time of the large outputs.
long minorFaults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

// Per-step times [ms] and minor page faults over the repetitions, in the order the steps were first timed.
class StepTimes {
 public:
  template <typename F>
  void time(const std::string& step, F&& work) {
    const long faults = minorFaults();
    const auto start = Clock::now();
    work();
    add(step, std::chrono::duration<double, std::milli>(Clock::now() - start).count(), minorFaults() - faults);
  }
  void add(const std::string& step, double ms, long faults) {
    if (!times_.count(step)) order_.push_back(step);
    times_[step].push_back(ms);
    faults_[step].push_back(double(faults));
  }
  const std::vector<std::string>& order() const { return order_; }
  const std::vector<double>& of(const std::string& step) const { return times_.at(step); }
  const std::vector<double>& faultsOf(const std::string& step) const { return faults_.at(step); }

 private:
  std::vector<std::string> order_;
  std::map<std::string, std::vector<double>> times_, faults_;
};

void printRow(const std::string& step, const std::vector<double>& ms, const std::vector<double>& faults,
              std::size_t bytes) {
  char line[160];
  std::snprintf(line, sizeof(line), "  %-44s %9.3f %9.3f %7.0f", step.c_str(), mc_flow::median(ms),
                mc_flow::percentile(ms, 0.9), mc_flow::median(faults));
  std::cout << line;
  if (bytes > 0) std::cout << "  " << bytes << " B";
  std::cout << "\n";
}

template <typename M>
std::size_t serialise(const M& message) {
  return ros::serialization::serializeMessage(message).num_bytes;
}

void writeFile(const std::string& path, const void* data, std::size_t bytes) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || std::fwrite(data, 1, bytes, f) != bytes || std::fclose(f) != 0)
    throw std::runtime_error("cannot write " + path);
}

template <typename M>
void dumpMessage(const std::string& path, const M& message) {
  const ros::SerializedMessage m = ros::serialization::serializeMessage(message);
  writeFile(path, m.buf.get(), m.num_bytes);
}

template <typename M>
void deserialise(const ros::SerializedMessage& arrived, M& message) {
  ros::serialization::IStream stream(arrived.message_start, std::uint32_t(arrived.num_bytes - 4));
  ros::serialization::deserialize(stream, message);
}

int run(int argc, char** argv) {
  mc_flow::CommandLine cli(
      "mcflow_bench_nodelet",
      {{"repetitions", true, "pairs timed per downsample factor (50)"},
       {"downsample", true, "comma-separated factors, 0 = automatic as the nodelet (0,1)"},
       {"size", true, "input WxH (640x480)"},
       {"variant", true, "synthetic scene variant (0)"},
       {"depth-noise", true, "synthetic depth noise [m] at 1 m, growing with depth^2 (0)"},
       {"real", true, "a real pair's folder (shared/data/real_pairs/NAME) instead of the synthetic scene"},
       {"dump", true,
        "write the first repetition's messages (serialised) and converted frame to DIR "
        "(to compare two builds byte for byte)"}});
  cli.parse(argc, argv);
  if (cli.helpRequested()) {
    std::cout << cli.usage();
    return 0;
  }
  const int repetitions = cli.integer("repetitions", 50, 1, 100000);
  mc_flow::SyntheticSceneOptions scene;
  const std::string size = cli.text("size", "640x480");
  if (std::sscanf(size.c_str(), "%dx%d", &scene.width, &scene.height) != 2 || scene.width < 16 || scene.height < 16)
    throw mc_flow::CommandLineError("--size " + size + ": expected WxH, at least 16x16");
  scene.variant = cli.integer("variant", 0, 0, mc_flow::syntheticVariantCount() - 1);
  scene.depth_noise = std::stod(cli.text("depth-noise", "0"));
  const std::string real = cli.text("real", "");
  mc_flow::Config config;
  cli.applySettings(config);
  const mc_flow_ros::NodeParameters defaults;

  const ros::Time t0(100, 0), t1(100, 33000000);
  const InputMessages m0 = real.empty() ? renderMessages(scene, 0, t0) : realMessages(real, 0, t0);
  const InputMessages m1 = real.empty() ? renderMessages(scene, 1, t1) : realMessages(real, 1, t1);
  const std::string input_name =
      real.empty() ? "synthetic variant " + std::to_string(scene.variant) +
                         (scene.depth_noise > 0 ? ", depth noise " + cli.text("depth-noise", "") + " m" : "")
                   : real;

  for (const std::string& factor_text : cli.list("downsample", "0,1")) {
    const int downsample = std::stoi(factor_text);
    // The nodelet's path to a Result: toFrameInput, then a pipeline at factor 1 (the frame is already at the
    // processing resolution), the FrameInput carried as the frame's extra.
    mc_flow::SequencePipeline pipeline(config, 1, defaults.max_pair_interval);
    auto push = [&](const InputMessages& m) {
      return pipeline.push(mc_flow_ros::toStreamFrame(
          mc_flow_ros::toFrameInput(m.rgb, m.depth, m.info, downsample, std::uint64_t(defaults.max_input_pixels),
                                    config.depth_downsample_range)));
    };
    push(m0);
    const auto solve_start = Clock::now();
    const mc_flow::SequenceStep step = push(m1);
    const double solve_ms = std::chrono::duration<double, std::milli>(Clock::now() - solve_start).count();
    if (step.outcome != mc_flow::SequenceStep::Outcome::Solved)
      throw std::runtime_error("the pair was not solved: " + mc_flow::toString(step.outcome) + " " + step.problem);
    const mc_flow::Result& result = *step.result;
    const auto& first = std::any_cast<const mc_flow_ros::FrameInput&>(step.first->extra);
    const auto& second = std::any_cast<const mc_flow_ros::FrameInput&>(step.second->extra);
    mc_flow_ros::PairContext pair;
    pair.header = second.header;
    pair.previous_stamp = first.header.stamp;
    pair.previous = &first;
    pair.current = &second;
    pair.previous_frame = &step.first->frame;
    pair.world = &step.world_velocities;
    // ~camera_path's poses as the nodelet holds them after a long stream.
    const std::deque<Eigen::Matrix4d> camera_poses(mc_flow_ros::OutputPublishers::kCameraPathPoses,
                                                   pipeline.odometry().pose);
    pair.solve_time_ms = cli.has("dump") ? 0.0 : solve_ms;  // a dump compares builds: no clock in it

    // What arrives from a driver in another process (the length prefix, then the message).
    const std::vector<ros::SerializedMessage> arrived = {ros::serialization::serializeMessage(m1.rgb),
                                                         ros::serialization::serializeMessage(m1.depth),
                                                         ros::serialization::serializeMessage(m1.info)};
    // The nodelet's message pools (OutputPublishers'): a pair's messages are reused by the next once released.
    mc_flow_ros::ImagePool soft_pool, labels_pool, occlusion_pool, segmentation_pool, moving_pool;
    mc_flow_ros::CloudPool cloud_pool;
    StepTimes own, alone, wire;
    std::map<std::string, std::size_t> bytes;
    std::size_t sink = 0;
    for (int r = 0; r < repetitions; ++r) {
      const auto pair_start = Clock::now();
      const long pair_faults = minorFaults();
      // ---- input: one new frame per pair (process(): toFrameInput, then the StreamFrame for the pipeline)
      mc_flow_ros::FrameInput input;
      own.time("toFrameInput (validation + conversion)", [&] {
        input = mc_flow_ros::toFrameInput(m1.rgb, m1.depth, m1.info, downsample,
                                          std::uint64_t(defaults.max_input_pixels), config.depth_downsample_range);
      });
      mc_flow::StreamFrame frame;
      own.time("StreamFrame (the frame and FrameInput moved)",
               [&] { frame = mc_flow_ros::toStreamFrame(std::move(input)); });
      sink += frame.frame.depth.data.size();
      // ---- outputs: publish() with a listener on every topic, then publishTf
      mc_flow::SegmentArray segments;
      sensor_msgs::ImagePtr soft, labels, occlusion, segmentation;
      sensor_msgs::PointCloud2Ptr cloud;
      visualization_msgs::MarkerArray markers;
      sensor_msgs::ImagePtr moving;
      nav_msgs::Odometry odom;
      nav_msgs::Path path;
      sensor_msgs::CameraInfo info;
      std::vector<geometry_msgs::TransformStamped> transforms;
      own.time("~segments", [&] { segments = mc_flow_ros::makeSegmentArray(result, pair); });
      // The three large outputs as the nodelet builds them: their rows in one parallel region (makeImageOutputs).
      own.time("~soft_labels, ~segmentation, ~scene_flow", [&] {
        mc_flow_ros::ImageOutputRequest request;
        request.soft_labels = request.segmentation = request.scene_flow = true;
        request.segmentation_blend = defaults.segmentation_blend;
        request.soft_labels_pool = &soft_pool;
        request.segmentation_pool = &segmentation_pool;
        request.cloud_pool = &cloud_pool;
        const mc_flow_ros::ImageOutputs built = mc_flow_ros::makeImageOutputs(result, pair, request);
        soft = built.soft_labels;
        segmentation = built.segmentation;
        cloud = built.scene_flow;
      });
      own.time("~labels", [&] { labels = mc_flow_ros::makeLabelsImage(result, pair, &labels_pool); });
      own.time("~occlusion", [&] { occlusion = mc_flow_ros::makeOcclusionImage(result, pair, &occlusion_pool); });
      own.time("~motion_markers",
               [&] { markers = mc_flow_ros::makeMotionMarkers(result, pair, defaults.marker_seconds_ahead); });
      own.time("~camera_info", [&] { info = mc_flow_ros::processingCameraInfo(*pair.current); });
      own.time("~moving_mask",
               [&] { moving = mc_flow_ros::makeMovingMaskImage(result, *pair.world, pair, &moving_pool); });
      own.time("~odom, ~camera_path", [&] {
        odom = mc_flow_ros::makeOdometry(pipeline.odometry(), pair.header.stamp, defaults.odom_frame,
                                         pair.header.frame_id, Eigen::Isometry3d::Identity());
        path = mc_flow_ros::makeCameraPath(camera_poses, pair.header);
      });
      own.time("TF transforms", [&] {
        transforms = mc_flow_ros::makeSegmentTransforms(result, pipeline.tracks(), pair, defaults.segment_frame_prefix);
      });
      own.add("total", std::chrono::duration<double, std::milli>(Clock::now() - pair_start).count(),
              minorFaults() - pair_faults);
      // The large outputs one by one (each make* function's own parallel region; not what the nodelet runs).
      alone.time("~soft_labels", [&] { sink += mc_flow_ros::makeSoftLabelsImage(result, pair)->data.size(); });
      alone.time("~segmentation", [&] {
        sink += mc_flow_ros::makeSegmentationImage(result, pair, defaults.segmentation_blend)->data.size();
      });
      alone.time("~scene_flow", [&] { sink += mc_flow_ros::makeSceneFlowCloud(result, pair)->data.size(); });

      // ---- the wire (not the nodelet's own code: roscpp serialises once per publish for remote subscribers,
      // and deserialises the inputs from a driver in another process; nodelets in one manager skip both)
      const auto wire_start = Clock::now();
      const long wire_faults = minorFaults();
      wire.time("~scene_flow cloud", [&] { bytes["~scene_flow cloud"] = serialise(*cloud); });
      wire.time("~soft_labels", [&] { bytes["~soft_labels"] = serialise(*soft); });
      wire.time("~segmentation", [&] { bytes["~segmentation"] = serialise(*segmentation); });
      wire.time("~labels", [&] { bytes["~labels"] = serialise(*labels); });
      wire.time("~occlusion", [&] { bytes["~occlusion"] = serialise(*occlusion); });
      wire.time("~segments + ~motion_markers + ~camera_info", [&] {
        bytes["~segments + ~motion_markers + ~camera_info"] =
            serialise(segments) + serialise(markers) + serialise(info);
      });
      wire.add("total (outputs)", std::chrono::duration<double, std::milli>(Clock::now() - wire_start).count(),
               minorFaults() - wire_faults);
      wire.time("inputs: deserialise rgb + depth + camera_info", [&] {
        sensor_msgs::Image rgb, depth;
        sensor_msgs::CameraInfo camera;
        deserialise(arrived[0], rgb);
        deserialise(arrived[1], depth);
        deserialise(arrived[2], camera);
        sink += rgb.data.size() + depth.data.size() + camera.D.size();
      });
      if (r == 0 && cli.has("dump")) {
        const std::string prefix = cli.text("dump", "") + "/downsample" + std::to_string(downsample) + "_";
        const mc_flow::RgbdFrame& converted = frame.frame;  // moved there out of the FrameInput
        writeFile(prefix + "intensity.f32", converted.intensity.data.data(), converted.intensity.data.size() * 4);
        writeFile(prefix + "depth.f32", converted.depth.data.data(), converted.depth.data.size() * 4);
        const cv::Mat& colour = std::any_cast<const mc_flow_ros::FrameInput&>(frame.extra).colour;
        writeFile(prefix + "colour.rgb", colour.data, colour.total() * colour.elemSize());
        dumpMessage(prefix + "segments.msg", segments);
        dumpMessage(prefix + "soft_labels.msg", *soft);
        dumpMessage(prefix + "labels.msg", *labels);
        dumpMessage(prefix + "occlusion.msg", *occlusion);
        dumpMessage(prefix + "segmentation.msg", *segmentation);
        dumpMessage(prefix + "scene_flow.msg", *cloud);
        dumpMessage(prefix + "markers.msg", markers);
        dumpMessage(prefix + "camera_info.msg", info);
        for (std::size_t i = 0; i < transforms.size(); ++i)
          dumpMessage(prefix + "tf" + std::to_string(i) + ".msg", transforms[i]);
      }
      sink += segments.segments.size() + soft->data.size() + labels->data.size() + occlusion->data.size() +
              segmentation->data.size() + cloud->data.size() + markers.markers.size() + info.D.size() +
              transforms.size() + moving->data.size() + path.poses.size() + odom.child_frame_id.size();
    }

    std::cout << "mcflow_bench_nodelet: " << input_name << ", input " << m1.rgb.width << "x" << m1.rgb.height
              << " rgb8 + 16UC1, downsample " << downsample << " -> factor " << first.downsample << ", outputs "
              << result.width << "x" << result.height << "; " << result.segments.size() << " segments, one solve "
              << std::lround(solve_ms) << " ms (" << result.backend << "); " << repetitions << " repetitions\n";
    std::cout << "  the nodelet's own work per pair (every output subscribed, publish_tf on)\n"
              << "                                               median [ms]  p90 [ms]  faults\n";
    for (const std::string& name : own.order()) printRow(name, own.of(name), own.faultsOf(name), 0);
    std::cout << "  the large outputs alone, each in its own parallel region (not in the total above)\n";
    for (const std::string& name : alone.order()) printRow(name, alone.of(name), alone.faultsOf(name), 0);
    std::cout << "  serialisation (remote subscribers / a driver in another process; not in the total above)\n";
    for (const std::string& name : wire.order())
      printRow(name, wire.of(name), wire.faultsOf(name), bytes.count(name) ? bytes.at(name) : std::size_t(0));
    std::cout << "  (checksum " << sink % 997 << ")\n\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const mc_flow::CommandLineError& e) {
    std::cerr << "mcflow_bench_nodelet: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "mcflow_bench_nodelet: " << e.what() << "\n";
    return 1;
  }
}
