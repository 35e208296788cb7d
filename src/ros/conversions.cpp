#include "mc_flow/ros/conversions.h"

#include "mc_flow/core/sequence.h"

#include <algorithm>
#include <any>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <sstream>
#include <utility>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include <boost/make_shared.hpp>
#include <cv_bridge/cv_bridge.h>
#include <opencv2/imgproc.hpp>
#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <tf2_eigen/tf2_eigen.h>

#include "mc_flow/core/se3.h"
#include "mc_flow/core/palette.h"

namespace enc = sensor_msgs::image_encodings;

namespace mc_flow_ros {

using mc_flow::colourForId;
using mc_flow::Rgb8;

namespace {

cv::Mat colourToRgb8(const cv_bridge::CvImageConstPtr& image, const std::string& encoding) {
  cv::Mat rgb;
  if (encoding == enc::RGB8) {
    rgb = image->image;
  } else if (encoding == enc::BGR8) {
    cv::cvtColor(image->image, rgb, cv::COLOR_BGR2RGB);
  } else if (encoding == enc::RGBA8) {
    cv::cvtColor(image->image, rgb, cv::COLOR_RGBA2RGB);
  } else if (encoding == enc::BGRA8) {
    cv::cvtColor(image->image, rgb, cv::COLOR_BGRA2RGB);
  } else if (encoding == enc::MONO8) {
    cv::cvtColor(image->image, rgb, cv::COLOR_GRAY2RGB);
  } else {  // mono16
    cv::Mat grey8;
    image->image.convertTo(grey8, CV_8U, 1.0 / 256.0);
    cv::cvtColor(grey8, rgb, cv::COLOR_GRAY2RGB);
  }
  return rgb;
}

// A cv::Mat over an ImageF's pixels: OpenCV writes into the core's image, no copy after.
cv::Mat matOver(mc_flow::ImageF& image) { return cv::Mat(image.height, image.width, CV_32F, image.ptr()); }

// One row of 8-bit RGB as intensity in [0, 1]: the one grey conversion (mc_flow::greyFromRgb, in double), as the
// synthetic frames make it. Built for AVX2 as well as the baseline (picked at load time): the same double operations
// four lanes wide (AVX2 alone does not enable FMA contraction), so the same bits.
__attribute__((target_clones("avx2", "default"))) void intensityRow(const std::uint8_t* rgb, int width, float* out) {
  for (int x = 0; x < width; ++x)
    out[x] = float(mc_flow::greyFromRgb(rgb[3 * x], rgb[3 * x + 1], rgb[3 * x + 2]) / 255.0);
}

/// Intensity in [0, 1] of the `crop` of the colour image (16-bit grey keeps its precision), written into `out`
/// (crop-sized).
void colourToIntensity(const cv_bridge::CvImageConstPtr& image, const std::string& encoding, const cv::Mat& rgb8,
                       const cv::Rect& crop, mc_flow::ImageF& out) {
  cv::Mat intensity = matOver(out);
  if (encoding == enc::MONO16) {
    image->image(crop).convertTo(intensity, CV_32F, 1.0 / 65535.0);
  } else if (encoding == enc::MONO8) {
    image->image(crop).convertTo(intensity, CV_32F, 1.0 / 255.0);
  } else {
#pragma omp parallel for schedule(static)
    for (int y = 0; y < crop.height; ++y)
      intensityRow(rgb8.ptr<std::uint8_t>(crop.y + y) + 3 * crop.x, crop.width, intensity.ptr<float>(y));
  }
  if (intensity.data != reinterpret_cast<const uchar*>(out.ptr()))
    throw std::logic_error("colourToIntensity: OpenCV reallocated the intensity image");
}

/// Depth in metres (0 = invalid) at the input resolution.
cv::Mat depthToMetres(const cv::Mat& image, const std::string& encoding) {
  cv::Mat metres(image.size(), CV_32F);
  if (encoding == enc::TYPE_16UC1) {
    image.convertTo(metres, CV_32F, 0.001);
  } else {
    image.copyTo(metres);
    for (int y = 0; y < metres.rows; ++y) {
      float* row = metres.ptr<float>(y);
      for (int x = 0; x < metres.cols; ++x) {
        if (!mc_flow::isValidDepth(row[x])) row[x] = 0.f;
      }
    }
  }
  return metres;
}

/// Depth in metres (0 = invalid) of the `crop` of a depth image of the colour image's size, written into `out`.
void depthToMetres(const cv::Mat& image, const std::string& encoding, const cv::Rect& crop, mc_flow::ImageF& out) {
  cv::Mat metres = matOver(out);
  if (encoding == enc::TYPE_16UC1) {
    image(crop).convertTo(metres, CV_32F, 0.001);
  } else {
    image(crop).copyTo(metres);
    for (float& z : out.data)
      if (!mc_flow::isValidDepth(z)) z = 0.f;
  }
  if (metres.data != reinterpret_cast<const uchar*>(out.ptr()))
    throw std::logic_error("depthToMetres: OpenCV reallocated the depth image");
}

// An image message of the size (from `pool` when given; its data keeps its memory when the size is the same), every
// field but the data set; the caller writes every byte of the data.
sensor_msgs::ImagePtr emptyImage(const PairContext& pair, int w, int h, const std::string& encoding,
                                 int bytes_per_pixel, ImagePool* pool) {
  auto msg = pool ? pool->take() : boost::make_shared<sensor_msgs::Image>();
  msg->header = pair.header;
  msg->width = std::uint32_t(w);
  msg->height = std::uint32_t(h);
  msg->encoding = encoding;
  msg->is_bigendian = false;
  msg->step = std::uint32_t(w * bytes_per_pixel);
  msg->data.resize(std::size_t(msg->step) * std::size_t(h));
  return msg;
}

// PCL's rgb field: 0x00RRGGBB in the bytes of a float.
std::uint32_t packedColour(const Rgb8& c) {
  return (std::uint32_t(c.r) << 16) | (std::uint32_t(c.g) << 8) | std::uint32_t(c.b);
}

}  // namespace

int countValidDepth(const std::vector<float>& depth) {
  // mc_flow::isValidDepth as two comparisons that vectorise (isfinite in the loop did not): NaN fails both, +inf the
  // second, -inf, zeros and negatives the first.
  constexpr float kInfinity = std::numeric_limits<float>::infinity();
  int valid = 0;
  for (const float z : depth) valid += int(z > 0.f) & int(z < kInfinity);
  return valid;
}

mc_flow::Intrinsics intrinsicsFromCameraInfo(const sensor_msgs::CameraInfo& info, int width, int height) {
  validateCameraInfo(info);
  const PinholeValues p = pinholeValues(info);
  // camera_info may describe the full sensor while the image is binned or scaled: rescale.
  const double sx = info.width > 0 ? double(width) / double(info.width) : 1.0;
  const double sy = info.height > 0 ? double(height) / double(info.height) : 1.0;
  return {p.fx * sx, p.fy * sy, (p.cx + 0.5) * sx - 0.5, (p.cy + 0.5) * sy - 0.5};
}

FrameInput toFrameInput(const sensor_msgs::Image& rgb_message, const sensor_msgs::Image& depth_message,
                        const sensor_msgs::CameraInfo& info, int downsample_request, std::uint64_t max_pixels,
                        double depth_range) {
  // Nothing below (cv_bridge, OpenCV) may read a buffer whose header has not been checked in 64 bits.
  const EncodingLayout rgb_layout = validateImage(rgb_message, ImageRole::Colour, max_pixels);
  const EncodingLayout depth_layout = validateImage(depth_message, ImageRole::Depth, max_pixels);
  validateCameraInfo(info, max_pixels);
  // Big-endian 16/32-bit values are swapped into a copy; host-order messages are read in place.
  std::optional<sensor_msgs::Image> rgb_swapped, depth_swapped;
  if (needsByteSwap(rgb_message, rgb_layout)) rgb_swapped = toHostByteOrder(rgb_message, rgb_layout);
  if (needsByteSwap(depth_message, depth_layout)) depth_swapped = toHostByteOrder(depth_message, depth_layout);
  const sensor_msgs::Image& rgb = rgb_swapped ? *rgb_swapped : rgb_message;
  const sensor_msgs::Image& depth = depth_swapped ? *depth_swapped : depth_message;

  const int w = int(rgb.width), h = int(rgb.height), dw = int(depth.width), dh = int(depth.height);
  // Same aspect ratio within one pixel of the larger image, else the images do not show the same view.
  if (std::abs(double(w) * dh - double(h) * dw) > double(std::max(w, dw)) + double(std::max(h, dh))) {
    throw FrameInputError(InputProblem::Size,
                          "RGB " + mc_flow::imageSizeText(w, h) + " and depth " + mc_flow::imageSizeText(dw, dh) +
                              " have different aspect ratios (is the depth registered to the colour camera?)");
  }
  const int factor = mc_flow::chooseDownsample(downsample_request, w);
  const int out_w = w / factor, out_h = h / factor;
  if (out_w < 16 || out_h < 16) {
    throw FrameInputError(InputProblem::Size, "processing size " + mc_flow::imageSizeText(out_w, out_h) + " (RGB " +
                                                  mc_flow::imageSizeText(w, h) + " / downsample " +
                                                  std::to_string(factor) + ") is too small");
  }

  cv_bridge::CvImageConstPtr rgb_cv, depth_cv;
  try {
    // The messages outlive these views (they are only read inside this function): no copy needed.
    rgb_cv = cv_bridge::toCvShare(rgb, boost::shared_ptr<void const>());
    depth_cv = cv_bridge::toCvShare(depth, boost::shared_ptr<void const>());
  } catch (const cv_bridge::Exception& e) {
    throw FrameInputError(InputProblem::Encoding, std::string("cv_bridge could not read the images: ") + e.what());
  }

  FrameInput out;
  out.header = rgb.header;
  out.downsample = factor;
  out.input_width = w;
  out.input_height = h;
  out.K = intrinsicsFromCameraInfo(info, w, h).scaled(1.0 / factor);

  const cv::Mat rgb8 = colourToRgb8(rgb_cv, rgb.encoding);
  // Crop to a multiple of the factor at the right/bottom: the principal point needs no change then.
  const cv::Rect crop(0, 0, out_w * factor, out_h * factor);
  // The solver's frame at the input resolution, converted straight into the core's images (no copies after).
  mc_flow::RgbdFrame full;
  full.intensity = mc_flow::ImageF(crop.width, crop.height, 1);
  full.depth = mc_flow::ImageF(crop.width, crop.height, 1);
  colourToIntensity(rgb_cv, rgb.encoding, rgb8, crop, full.intensity);
  if (dw != w || dh != h) {  // registered depth of another resolution: nearest keeps real measurements
    cv::Mat resized;
    cv::resize(depthToMetres(depth_cv->image, depth.encoding), resized, cv::Size(w, h), 0, 0, cv::INTER_NEAREST);
    depthToMetres(resized, enc::TYPE_32FC1, crop, full.depth);  // zeros stay zeros: a plain copy
  } else {
    depthToMetres(depth_cv->image, depth.encoding, crop, full.depth);
  }
  // The solver's frame: the core's downsampling rule (the pyramid's), as `mcflow run-seq` uses it. The
  // colour picture is for display only.
  cv::Mat colour_small;
  if (factor == 1)
    colour_small = rgb8(crop).clone();
  else
    cv::resize(rgb8(crop), colour_small, cv::Size(out_w, out_h), 0, 0, cv::INTER_AREA);
  out.colour = colour_small;
  out.frame = factor == 1 ? std::move(full) : mc_flow::downsampleFrame(std::move(full), factor, depth_range);
  out.valid_depth = countValidDepth(out.frame.depth.data);
  if (out.valid_depth == 0) {
    throw FrameInputError(InputProblem::Depth, "depth image (" + depth.encoding + ", " +
                                                   mc_flow::imageSizeText(dw, dh) +
                                                   ") has no valid pixel: all zero or NaN");
  }
  return out;
}

sensor_msgs::CameraInfo processingCameraInfo(const FrameInput& input) {
  sensor_msgs::CameraInfo info;
  info.header = input.header;
  info.width = std::uint32_t(input.colour.cols);  // the processing resolution (the frame has moved to the pipeline)
  info.height = std::uint32_t(input.colour.rows);
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);  // the inputs are rectified
  info.K = {input.K.fx, 0, input.K.cx, 0, input.K.fy, input.K.cy, 0, 0, 1};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.P = {input.K.fx, 0, input.K.cx, 0, 0, input.K.fy, input.K.cy, 0, 0, 0, 1, 0};
  return info;
}

mc_flow::StreamFrame toStreamFrame(FrameInput input) {
  mc_flow::StreamFrame frame;
  frame.frame = std::move(input.frame);  // the pipeline keeps it; outputs read it there (PairContext::previous_frame)
  input.frame = mc_flow::RgbdFrame();    // 0x0, not sizes without data
  frame.K = input.K;
  frame.stamp = input.header.stamp.toSec();
  frame.source = input.header.frame_id;
  frame.extra = std::move(input);
  return frame;
}

PairContext pairContext(const mc_flow::SequenceStep& step, double solve_ms) {
  PairContext pair;
  pair.previous = &std::any_cast<const FrameInput&>(step.first->extra);
  pair.current = &std::any_cast<const FrameInput&>(step.second->extra);
  pair.previous_frame = &step.first->frame;
  pair.header = pair.current->header;
  pair.previous_stamp = pair.previous->header.stamp;
  pair.solve_time_ms = solve_ms;
  pair.world = &step.world_velocities;
  return pair;
}

Eigen::Vector3d centroidVelocity(const mc_flow::Segment& segment, double interval) {
  const Eigen::Vector3d moved =
      segment.transform.topLeftCorner<3, 3>() * segment.centroid + segment.transform.topRightCorner<3, 1>();
  return (moved - segment.centroid) / interval;
}

mc_flow::SegmentArray makeSegmentArray(const mc_flow::Result& result, const PairContext& pair) {
  mc_flow::SegmentArray msg;
  msg.header = pair.header;
  msg.previous_stamp = pair.previous_stamp;
  msg.width = std::uint32_t(result.width);
  msg.height = std::uint32_t(result.height);
  msg.backend = result.backend;
  msg.solve_time_ms = pair.solve_time_ms;
  msg.start = mc_flow::toString(result.start);
  msg.start_note = result.start_note;
  msg.world_chosen_by = result.world.found ? result.world.chosen_by : std::string();
  const double dt = pair.interval();
  for (std::size_t i = 0; i < result.segments.size(); ++i) {
    const mc_flow::Segment& s = result.segments[i];
    mc_flow::MotionSegment out;
    out.id = std::uint32_t(s.id);
    out.twist.linear.x = s.twist(0) / dt;
    out.twist.linear.y = s.twist(1) / dt;
    out.twist.linear.z = s.twist(2) / dt;
    out.twist.angular.x = s.twist(3) / dt;
    out.twist.angular.y = s.twist(4) / dt;
    out.twist.angular.z = s.twist(5) / dt;
    out.transform = tf2::eigenToTransform(Eigen::Isometry3d(s.transform)).transform;
    out.support = s.support;
    out.centroid.x = s.centroid.x();
    out.centroid.y = s.centroid.y();
    out.centroid.z = s.centroid.z();
    const Rgb8 c = mc_flow::displayColour(out.id, result.world.ids);
    out.color.r = c.r / 255.f;
    out.color.g = c.g / 255.f;
    out.color.b = c.b / 255.f;
    out.color.a = 1.f;
    if (pair.world && i < pair.world->size()) {
      const mc_flow::WorldVelocity& w = (*pair.world)[i];
      out.world = result.world.contains(s.id);
      out.moving = w.moving;
      out.world_velocity.linear.x = w.linear.x();
      out.world_velocity.linear.y = w.linear.y();
      out.world_velocity.linear.z = w.linear.z();
      out.world_velocity.angular.x = w.angular.x();
      out.world_velocity.angular.y = w.angular.y();
      out.world_velocity.angular.z = w.angular.z();
      for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c) out.world_velocity_covariance[std::size_t(6 * r + c)] = w.covariance(r, c);
    }
    msg.segments.push_back(out);
  }
  long outliers = 0;
  for (std::int32_t label : result.labels.data) outliers += label <= 0 ? 1 : 0;
  msg.outlier_support = double(outliers);
  return msg;
}

namespace {

sensor_msgs::ImagePtr emptySoftLabelsImage(const mc_flow::Result& result, const PairContext& pair, ImagePool* pool) {
  const mc_flow::SoftLabels& u = result.soft_labels;
  const int n = std::max(u.count, 1);
  return emptyImage(pair, u.width, u.height, "32FC" + std::to_string(n), int(sizeof(float)) * n, pool);
}

// interleaveSoftLabels one float at a time.
void interleavePlanes(const mc_flow::SoftLabels& u, std::size_t begin, std::size_t end, float* out) {
  const std::size_t n = std::size_t(u.count);
  for (std::size_t p = begin; p < end; ++p)
    for (std::size_t c = 0; c < n; ++c) out[p * n + c] = u.plane(int(c))[p];
}

#if defined(__x86_64__) && defined(__GNUC__)
// interleaveSoftLabels for 2-8 planes with AVX2: 8 pixels of every plane transposed in registers (8 x 8, the missing
// planes zero) and stored a pixel at a time, 8 floats wide, in order: a store's spill past its pixel's n floats lands
// on the following pixels, which later stores overwrite. A store that would reach past the range's last float is copied
// n floats wide instead (another thread may own what follows, or the buffer ends). The same floats, moved, not
// computed; 2-3 x faster than one float at a time on the VM.
__attribute__((target("avx2"))) void interleavePlanesAvx2(const mc_flow::SoftLabels& u, std::size_t begin,
                                                          std::size_t end, float* out) {
  const std::size_t n = std::size_t(u.count), last_float = end * n;
  std::size_t p = begin;
  for (; p + 8 <= end; p += 8) {
    __m256 r[8];
    for (std::size_t c = 0; c < 8; ++c) r[c] = c < n ? _mm256_loadu_ps(u.plane(int(c)) + p) : _mm256_setzero_ps();
    const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]),
                 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]),
                 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]),
                 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
    const __m256 s0 = _mm256_shuffle_ps(t0, t2, 0x44), s1 = _mm256_shuffle_ps(t0, t2, 0xEE),
                 s2 = _mm256_shuffle_ps(t1, t3, 0x44), s3 = _mm256_shuffle_ps(t1, t3, 0xEE),
                 s4 = _mm256_shuffle_ps(t4, t6, 0x44), s5 = _mm256_shuffle_ps(t4, t6, 0xEE),
                 s6 = _mm256_shuffle_ps(t5, t7, 0x44), s7 = _mm256_shuffle_ps(t5, t7, 0xEE);
    // pixel[k]: its n plane values in the first n lanes.
    const __m256 pixel[8] = {_mm256_permute2f128_ps(s0, s4, 0x20), _mm256_permute2f128_ps(s1, s5, 0x20),
                             _mm256_permute2f128_ps(s2, s6, 0x20), _mm256_permute2f128_ps(s3, s7, 0x20),
                             _mm256_permute2f128_ps(s0, s4, 0x31), _mm256_permute2f128_ps(s1, s5, 0x31),
                             _mm256_permute2f128_ps(s2, s6, 0x31), _mm256_permute2f128_ps(s3, s7, 0x31)};
    for (std::size_t k = 0; k < 8; ++k) {
      const std::size_t at = (p + k) * n;
      if (at + 8 <= last_float) {
        _mm256_storeu_ps(out + at, pixel[k]);
      } else {
        alignas(32) float values[8];
        _mm256_store_ps(values, pixel[k]);
        std::memcpy(out + at, values, n * sizeof(float));
      }
    }
  }
  interleavePlanes(u, p, end, out);
}
#endif

}  // namespace

void interleaveSoftLabels(const mc_flow::SoftLabels& labels, std::size_t begin, std::size_t end, float* out) {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool avx2 = __builtin_cpu_supports("avx2");
  if (avx2 && labels.count >= 2 && labels.count <= 8) return interleavePlanesAvx2(labels, begin, end, out);
#endif
  interleavePlanes(labels, begin, end, out);
}

namespace {

// Rows [first_row, end_row) of the soft labels, planes interleaved per pixel into `message` (emptySoftLabelsImage's).
void fillSoftLabelRows(const mc_flow::SoftLabels& u, int first_row, int end_row, sensor_msgs::Image& message) {
  const std::size_t width = std::size_t(u.width);
  interleaveSoftLabels(u, std::size_t(first_row) * width, std::size_t(end_row) * width,
                       reinterpret_cast<float*>(message.data.data()));
}

}  // namespace

sensor_msgs::ImagePtr makeSoftLabelsImage(const mc_flow::Result& result, const PairContext& pair, ImagePool* pool) {
  auto msg = emptySoftLabelsImage(result, pair, pool);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < result.soft_labels.height; ++y) fillSoftLabelRows(result.soft_labels, y, y + 1, *msg);
  return msg;
}

sensor_msgs::ImagePtr makeLabelsImage(const mc_flow::Result& result, const PairContext& pair, ImagePool* pool) {
  auto msg = emptyImage(pair, result.labels.width, result.labels.height, enc::MONO16, 2, pool);
  auto* out = reinterpret_cast<std::uint16_t*>(msg->data.data());
  for (std::size_t i = 0; i < result.labels.pixelCount(); ++i) {
    out[i] = std::uint16_t(std::min<std::uint32_t>(std::uint32_t(std::max(0, result.labels.data[i])), 65535u));
  }
  return msg;
}

nav_msgs::Odometry makeOdometry(const mc_flow::Odometry& odometry, const ros::Time& stamp,
                                const std::string& odom_frame, const std::string& child_frame,
                                const Eigen::Isometry3d& base_from_camera) {
  const Eigen::Matrix4d M = base_from_camera.matrix();
  const Eigen::Matrix4d pose = M * odometry.pose * M.inverse();
  // Twists and right perturbations of the camera, expressed in the base frame: the adjoint of the mount.
  const Eigen::Matrix<double, 6, 6> mount = mc_flow::se3Adjoint(M);
  // The pose's covariance is of a perturbation exp(d) on the right of the base's pose: its position error is R d_v and
  // its orientation error R d_w in odom_frame (what nav_msgs/Odometry's covariance means), R the base's rotation.
  Eigen::Matrix<double, 6, 6> rotate = Eigen::Matrix<double, 6, 6>::Zero();
  rotate.topLeftCorner<3, 3>() = pose.topLeftCorner<3, 3>();
  rotate.bottomRightCorner<3, 3>() = pose.topLeftCorner<3, 3>();
  const Eigen::Matrix<double, 6, 6> to_odom = rotate * mount;
  const Eigen::Matrix<double, 6, 6> pose_cov = to_odom * odometry.pose_covariance * to_odom.transpose();
  const mc_flow::Vector6d velocity = mount * odometry.velocity;
  const Eigen::Matrix<double, 6, 6> velocity_cov = mount * odometry.velocity_covariance * mount.transpose();
  nav_msgs::Odometry msg;
  msg.header.stamp = stamp;
  msg.header.frame_id = odom_frame;
  msg.child_frame_id = child_frame;
  msg.pose.pose = tf2::toMsg(Eigen::Isometry3d(pose));
  msg.twist.twist.linear.x = velocity(0);
  msg.twist.twist.linear.y = velocity(1);
  msg.twist.twist.linear.z = velocity(2);
  msg.twist.twist.angular.x = velocity(3);
  msg.twist.twist.angular.y = velocity(4);
  msg.twist.twist.angular.z = velocity(5);
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) {
      msg.pose.covariance[std::size_t(6 * r + c)] = pose_cov(r, c);
      msg.twist.covariance[std::size_t(6 * r + c)] = velocity_cov(r, c);
    }
  return msg;
}

sensor_msgs::ImagePtr makeMovingMaskImage(const mc_flow::Result& result,
                                          const std::vector<mc_flow::WorldVelocity>& world, const PairContext& pair,
                                          ImagePool* pool) {
  auto msg = emptyImage(pair, result.labels.width, result.labels.height, enc::MONO8, 1, pool);
  mc_flow::movingMaskInto(result, world, msg->data.data());
  return msg;
}

sensor_msgs::ImagePtr makeOcclusionImage(const mc_flow::Result& result, const PairContext& pair, ImagePool* pool) {
  auto msg = emptyImage(pair, result.occlusion.width, result.occlusion.height, enc::MONO8, 1, pool);
  std::copy(result.occlusion.data.begin(), result.occlusion.data.end(), msg->data.begin());
  return msg;
}

namespace {

// The segment ids of the soft-label planes (0 for a plane without a segment) and the grey they are blended with: the
// previous frame's (the solver's intensity).
std::vector<int> planeIds(const mc_flow::Result& result) {
  std::vector<int> ids;
  for (int c = 0; c + 1 < result.soft_labels.count; ++c)
    ids.push_back(std::size_t(c) < result.segments.size() ? result.segments[std::size_t(c)].id : 0);
  return ids;
}

const mc_flow::ImageF* pictureGrey(const PairContext& pair) {
  return pair.firstFrame() ? &pair.firstFrame()->intensity : nullptr;
}

}  // namespace

cv::Mat segmentationPicture(const mc_flow::Result& result, const PairContext& pair, double blend) {
  const mc_flow::SoftLabels& u = result.soft_labels;
  cv::Mat picture(u.height, u.width, CV_8UC3);  // continuous: rows of width * 3 bytes
  mc_flow::segmentationPictureInto(u, planeIds(result), pictureGrey(pair), blend, result.world.ids, picture.data);
  return picture;
}

sensor_msgs::ImagePtr makeSegmentationImage(const mc_flow::Result& result, const PairContext& pair, double blend,
                                            ImagePool* pool) {
  const mc_flow::SoftLabels& u = result.soft_labels;
  auto msg = emptyImage(pair, u.width, u.height, enc::RGB8, 3, pool);
  mc_flow::segmentationPictureInto(u, planeIds(result), pictureGrey(pair), blend, result.world.ids, msg->data.data());
  return msg;
}

sensor_msgs::ImagePtr makeSegmentationImage(const cv::Mat& picture, const PairContext& pair, ImagePool* pool) {
  if (picture.type() != CV_8UC3)
    throw std::invalid_argument("makeSegmentationImage: the picture is not CV_8UC3 (type " +
                                std::to_string(picture.type()) + ")");
  auto msg = emptyImage(pair, picture.cols, picture.rows, enc::RGB8, 3, pool);
  const std::size_t row_bytes = std::size_t(picture.cols) * 3;
  for (int y = 0; y < picture.rows; ++y)
    std::memcpy(msg->data.data() + std::size_t(y) * row_bytes, picture.ptr<std::uint8_t>(y), row_bytes);
  return msg;
}

namespace {

sensor_msgs::PointCloud2Ptr emptySceneFlowCloud(const mc_flow::Result& result, const PairContext& pair,
                                                CloudPool* pool) {
  // From the pool: the data keeps its memory at the same size; every byte of every point (its padding too) is
  // written by SceneFlowCloudWriter.
  auto cloud = pool ? pool->take() : boost::make_shared<sensor_msgs::PointCloud2>();
  cloud->header = pair.header;
  cloud->height = std::uint32_t(result.height);
  cloud->width = std::uint32_t(result.width);
  sensor_msgs::PointCloud2Modifier modifier(*cloud);
  modifier.setPointCloud2Fields(9, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32,
                                "z", 1, sensor_msgs::PointField::FLOAT32, "rgb", 1, sensor_msgs::PointField::FLOAT32,
                                "vx", 1, sensor_msgs::PointField::FLOAT32, "vy", 1, sensor_msgs::PointField::FLOAT32,
                                "vz", 1, sensor_msgs::PointField::FLOAT32, "label", 1, sensor_msgs::PointField::UINT32,
                                "occluded", 1, sensor_msgs::PointField::UINT8);
  // Pad each point to a multiple of 4 bytes (33 -> 36): with 33, every other point's floats would sit at
  // unaligned addresses (undefined behaviour for the float iterators; UBSan reports it). The fields keep their
  // offsets; readers use point_step.
  cloud->point_step = (cloud->point_step + 3u) / 4u * 4u;
  modifier.resize(std::size_t(result.width) * std::size_t(result.height));
  // resize() flattens the cloud to one row: make it organized again (one point per pixel).
  cloud->height = std::uint32_t(result.height);
  cloud->width = std::uint32_t(result.width);
  cloud->row_step = cloud->width * cloud->point_step;
  cloud->is_dense = false;
  return cloud;
}

// Fills the points of an emptySceneFlowCloud by ranges of rows: each field stored straight into the point (a local
// point copied whole stalled on its store forwarding), in the layout of the fields, which is checked, not assumed.
class SceneFlowCloudWriter {
 public:
  SceneFlowCloudWriter(const mc_flow::Result& result, const PairContext& pair, CloudColour colour,
                       sensor_msgs::PointCloud2& cloud)
      : result_(result), cloud_(cloud) {
    const auto offset = [&](const std::string& name) {
      for (const sensor_msgs::PointField& f : cloud.fields)
        if (f.name == name) return std::size_t(f.offset);
      throw std::logic_error("scene-flow cloud: no field " + name);
    };
    if (cloud.point_step != kPointBytes || offset("x") != 0 || offset("y") != 4 || offset("z") != 8 ||
        offset("rgb") != kAtRgb || offset("vx") != kAtV || offset("label") != kAtLabel ||
        offset("occluded") != kAtOccluded)
      throw std::logic_error("scene-flow cloud: the fields' layout is not the one this writer fills");
    first_ = pair.previous;
    first_frame_ = pair.firstFrame();
    have_depth_ = first_frame_ && first_frame_->depth.sameSize(result.width, result.height);
    const bool have_colour = first_ && first_->colour.cols == result.width && first_->colour.rows == result.height;
    image_colour_ = colour == CloudColour::Image && have_colour;
    have_flow_ = result.scene_flow.sameSize(result.width, result.height) && result.scene_flow.channels >= 3;
    have_occlusion_ = !result.occlusion.empty();
    // (x - cx) / fx per column and (y - cy) / fy per row: the same doubles as per pixel, two divisions fewer each.
    const mc_flow::Intrinsics K = first_ ? first_->K : result.intrinsics;
    ray_x_.resize(std::size_t(std::max(result.width, 0)));
    ray_y_.resize(std::size_t(std::max(result.height, 0)));
    for (int x = 0; x < result.width; ++x) ray_x_[std::size_t(x)] = (x - K.cx) / K.fx;
    for (int y = 0; y < result.height; ++y) ray_y_[std::size_t(y)] = (y - K.cy) / K.fy;
    // Segment colours by id, up to the largest segment id (a palette look-up per pixel, fmod and lround, cost more
    // than the rest of a point; ids at noisy boundaries change too often to keep the last one's). Id 0 (outlier, no
    // depth) in its own grey, as a row that starts with it.
    int largest = 0;
    for (const mc_flow::Segment& s : result.segments) largest = std::max(largest, s.id);
    colour_of_id_.resize(std::size_t(largest) + 1);
    colour_of_id_[0] = packedColour(mc_flow::colourForId(0));
    for (int id = 1; id <= largest; ++id)
      colour_of_id_[std::size_t(id)] = packedColour(mc_flow::displayColour(std::uint32_t(id), result.world.ids));
  }

  void fillRows(int first_row, int end_row) const {
    const mc_flow::Result& result = result_;
    if (result.width <= 0) return;  // no points (and no row to point into)
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const bool have_labels = !result.labels.empty();
    const std::size_t flow_channels = have_flow_ ? std::size_t(result.scene_flow.channels) : 0;
    const auto put = [](std::uint8_t* to, auto value) { std::memcpy(to, &value, sizeof value); };
    for (int y = first_row; y < end_row; ++y) {
      const float* depth_row = have_depth_ ? &first_frame_->depth(0, y) : nullptr;
      const float* flow_row = have_flow_ ? &result.scene_flow(0, y, 0) : nullptr;
      const std::int32_t* label_row = have_labels ? &result.labels(0, y) : nullptr;
      const std::uint8_t* occlusion_row = have_occlusion_ ? &result.occlusion(0, y) : nullptr;
      const cv::Vec3b* colour_row = image_colour_ ? first_->colour.ptr<cv::Vec3b>(y) : nullptr;
      const double ray_row = ray_y_[std::size_t(y)];
      std::uint8_t* point = cloud_.data.data() + std::size_t(y) * std::size_t(cloud_.row_step);
      for (int x = 0; x < result.width; ++x, point += kPointBytes) {
        const float z = depth_row ? depth_row[x] : nan;
        const bool valid = mc_flow::isValidDepth(z);
        const float px = valid ? float(ray_x_[std::size_t(x)] * z) : nan, py = valid ? float(ray_row * z) : nan,
                    pz = valid ? z : nan;
        const bool flow_ok = valid && flow_row;
        const float* flow = flow_ok ? flow_row + flow_channels * std::size_t(x) : nullptr;
        const float vx = flow_ok ? flow[0] : nan, vy = flow_ok ? flow[1] : nan, vz = flow_ok ? flow[2] : nan;
        const std::uint32_t id = label_row ? std::uint32_t(std::max(0, label_row[x])) : 0u;
        std::uint32_t rgb;
        if (colour_row) {
          const cv::Vec3b& p = colour_row[x];
          rgb = packedColour({p[0], p[1], p[2]});
        } else {
          rgb = id < colour_of_id_.size() ? colour_of_id_[id]
                                          : packedColour(mc_flow::displayColour(id, result.world.ids));
        }
#if defined(__x86_64__)
        // x y z rgb and vx vy vz label as two 16-byte stores built in registers (x86-64 keeps floats in SSE registers,
        // so the id's and colour's bits pass unchanged; a vector built through memory stalled on store forwarding).
        const auto asFloat = [](std::uint32_t bits) {
          return _mm_cvtss_f32(_mm_castsi128_ps(_mm_cvtsi32_si128(int(bits))));
        };
        _mm_storeu_ps(reinterpret_cast<float*>(point), _mm_setr_ps(px, py, pz, asFloat(rgb)));
        _mm_storeu_ps(reinterpret_cast<float*>(point + kAtV), _mm_setr_ps(vx, vy, vz, asFloat(id)));
#else
        put(point, px);
        put(point + 4, py);
        put(point + 8, pz);
        put(point + kAtRgb, rgb);
        put(point + kAtV, vx);
        put(point + kAtV + 4, vy);
        put(point + kAtV + 8, vz);
        put(point + kAtLabel, id);
#endif
        // The occluded byte and the padding after it (zeros) as one word, the byte first in memory (a 4-byte array
        // copied instead went through memory and stalled on store forwarding).
        const std::uint32_t occluded = (occlusion_row && occlusion_row[x] > 0) ? 1u : 0u;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
        put(point + kAtOccluded, occluded << 24);
#else
        put(point + kAtOccluded, occluded);
#endif
      }
    }
  }

 private:
  static constexpr std::size_t kPointBytes = 36, kAtRgb = 12, kAtV = 16, kAtLabel = 28, kAtOccluded = 32;
  const mc_flow::Result& result_;
  sensor_msgs::PointCloud2& cloud_;
  const FrameInput* first_ = nullptr;
  const mc_flow::RgbdFrame* first_frame_ = nullptr;
  bool have_depth_ = false, image_colour_ = false, have_flow_ = false, have_occlusion_ = false;
  std::vector<double> ray_x_, ray_y_;
  std::vector<std::uint32_t> colour_of_id_;  // packed rgb per id 0 .. the largest segment id
};

}  // namespace

sensor_msgs::PointCloud2Ptr makeSceneFlowCloud(const mc_flow::Result& result, const PairContext& pair,
                                               CloudColour colour, CloudPool* pool) {
  auto cloud = emptySceneFlowCloud(result, pair, pool);
  const SceneFlowCloudWriter writer(result, pair, colour, *cloud);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < result.height; ++y) writer.fillRows(y, y + 1);
  return cloud;
}

ImageOutputs makeImageOutputs(const mc_flow::Result& result, const PairContext& pair,
                              const ImageOutputRequest& request) {
  ImageOutputs out;
  // Each message prepared as its make* function prepares it; then their rows in blocks, all in one parallel region.
  std::optional<mc_flow::SegmentationPainter> painter;
  std::optional<SceneFlowCloudWriter> writer;
  if (request.soft_labels) out.soft_labels = emptySoftLabelsImage(result, pair, request.soft_labels_pool);
  if (request.segmentation) {
    const mc_flow::SoftLabels& u = result.soft_labels;
    out.segmentation = emptyImage(pair, u.width, u.height, enc::RGB8, 3, request.segmentation_pool);
    painter.emplace(u, planeIds(result), pictureGrey(pair), request.segmentation_blend, result.world.ids);
  }
  if (request.scene_flow) {
    out.scene_flow = emptySceneFlowCloud(result, pair, request.cloud_pool);
    writer.emplace(result, pair, request.cloud_colour, *out.scene_flow);
  }
  enum class Output { SoftLabels, Segmentation, SceneFlow };
  struct Block {
    Output output;
    int first_row, end_row;
  };
  constexpr int kRowsPerBlock = 16;
  std::vector<Block> blocks;
  auto addRows = [&](Output output, int rows) {
    for (int y = 0; y < rows; y += kRowsPerBlock) blocks.push_back({output, y, std::min(rows, y + kRowsPerBlock)});
  };
  if (out.soft_labels) addRows(Output::SoftLabels, result.soft_labels.height);
  if (painter) addRows(Output::Segmentation, result.soft_labels.height);
  if (writer) addRows(Output::SceneFlow, result.height);
#pragma omp parallel for schedule(dynamic, 1)
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const Block& block = blocks[b];
    switch (block.output) {
      case Output::SoftLabels:
        fillSoftLabelRows(result.soft_labels, block.first_row, block.end_row, *out.soft_labels);
        break;
      case Output::Segmentation:
        painter->paintRows(block.first_row, block.end_row, out.segmentation->data.data());
        break;
      case Output::SceneFlow: writer->fillRows(block.first_row, block.end_row); break;
    }
  }
  return out;
}

std::vector<geometry_msgs::TransformStamped> makeSegmentTransforms(const mc_flow::Result& result,
                                                                   const std::map<int, mc_flow::SegmentTrack>& tracks,
                                                                   const PairContext& pair, const std::string& prefix) {
  std::vector<geometry_msgs::TransformStamped> transforms;
  for (const mc_flow::Segment& s : result.segments) {
    const auto track = tracks.find(s.id);
    if (track == tracks.end()) continue;
    // The segment's accumulated rotation, placed at its centroid moved to this frame.
    Eigen::Isometry3d frame = Eigen::Isometry3d::Identity();
    frame.linear() = track->second.pose.topLeftCorner<3, 3>();
    frame.translation() = track->second.origin;
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(frame);
    t.header = pair.header;
    t.child_frame_id = prefix + std::to_string(s.id);
    transforms.push_back(t);
  }
  return transforms;
}

visualization_msgs::MarkerArray makeMotionMarkers(const mc_flow::Result& result, const PairContext& pair,
                                                  double seconds_ahead) {
  visualization_msgs::MarkerArray markers;
  visualization_msgs::Marker clear;
  clear.header = pair.header;
  clear.action = visualization_msgs::Marker::DELETEALL;
  markers.markers.push_back(clear);
  const double dt = pair.interval();
  // With the static world known, arrows show what moves in the world, at its world-relative velocity; the world and
  // what rests in it get none. Without it, every segment's motion relative to the camera.
  const bool world_known = pair.world && pair.world->size() == result.segments.size() && result.world.found;
  for (std::size_t i = 0; i < result.segments.size(); ++i) {
    const mc_flow::Segment& s = result.segments[i];
    if (world_known && !(*pair.world)[i].moving) continue;
    const std::uint32_t id = std::uint32_t(result.segments[i].id);
    const Rgb8 c = colourForId(id);
    const Eigen::Vector3d velocity = world_known ? (*pair.world)[i].linear : centroidVelocity(s, dt);
    const Eigen::Vector3d tip = s.centroid + velocity * seconds_ahead;

    visualization_msgs::Marker arrow;
    arrow.header = pair.header;
    arrow.ns = "motion";
    arrow.id = int(id);
    arrow.type = visualization_msgs::Marker::ARROW;
    arrow.action = visualization_msgs::Marker::ADD;
    arrow.pose.orientation.w = 1.0;
    geometry_msgs::Point start, end;
    start.x = s.centroid.x();
    start.y = s.centroid.y();
    start.z = s.centroid.z();
    end.x = tip.x();
    end.y = tip.y();
    end.z = tip.z();
    arrow.points = {start, end};
    arrow.scale.x = 0.01;  // shaft diameter [m]
    arrow.scale.y = 0.02;  // head diameter [m]
    arrow.scale.z = 0.03;  // head length [m]
    arrow.color.r = c.r / 255.f;
    arrow.color.g = c.g / 255.f;
    arrow.color.b = c.b / 255.f;
    arrow.color.a = 1.f;
    markers.markers.push_back(arrow);

    visualization_msgs::Marker text = arrow;
    text.ns = "label";
    text.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    text.points.clear();
    text.pose.position = start;
    text.pose.position.y -= 0.05;  // above the centroid (y points down in the optical frame)
    text.scale.x = text.scale.y = 0;
    text.scale.z = 0.05;  // text height [m]
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), "%u: %.2f m/s", id, velocity.norm());
    text.text = buffer;
    markers.markers.push_back(text);
  }
  return markers;
}

nav_msgs::Path makeCameraPath(const std::deque<Eigen::Matrix4d>& poses, const std_msgs::Header& header) {
  nav_msgs::Path path;
  path.header = header;
  if (poses.empty()) return path;
  const Eigen::Matrix4d now_from_odom = poses.back().inverse();
  for (const Eigen::Matrix4d& pose : poses) {
    geometry_msgs::PoseStamped p;
    p.header = header;
    p.pose = tf2::toMsg(Eigen::Isometry3d(Eigen::Matrix4d(now_from_odom * pose)));
    path.poses.push_back(p);
  }
  return path;
}

}  // namespace mc_flow_ros
