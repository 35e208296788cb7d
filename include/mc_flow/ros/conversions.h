/**
 * @file conversions.h
 * @brief ROS messages <-> core types: camera images to mc_flow::RgbdFrame, mc_flow::Result to the
 * nodelet's output messages. No node needed (unit-tested in test/ros/test_conversions.cpp).
 *
 * Frames (REP 103): everything stays in the input camera's optical frame (x right, y down, z forward).
 * Output images are at the processing resolution (the input resolution divided by the downsample factor).
 */
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>
#include <Eigen/Geometry>
#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <visualization_msgs/MarkerArray.h>

#include "mc_flow/ros/message_pool.h"
#include "mc_flow/SegmentArray.h"
#include "mc_flow/core/error.h"
#include "mc_flow/core/image.h"
#include "mc_flow/core/sequence.h"
#include "mc_flow/core/solver.h"
#include "mc_flow/ros/input_error.h"
#include "mc_flow/ros/message_validation.h"

namespace mc_flow_ros {

/// @brief One synchronised RGB-D frame, converted and resized to the processing resolution.
struct FrameInput {
  mc_flow::RgbdFrame frame;  ///< intensity [0, 1], depth [m] (0 = invalid); 0x0 once toStreamFrame moved it out
  cv::Mat colour;           ///< CV_8UC3 RGB at the processing resolution (for display outputs; its size is the frame's)
  mc_flow::Intrinsics K;    ///< [px] at the processing resolution
  std_msgs::Header header;  ///< stamp and frame_id of the RGB image
  int downsample = 1;       ///< input pixels per processing pixel (per axis)
  int input_width = 0, input_height = 0;  ///< RGB image size
  int valid_depth = 0;                    ///< pixels with valid depth at the processing resolution
};

/// @brief Pinhole intrinsics of an image of `width` x `height` pixels from camera_info. Uses P (the
/// rectified projection), falling back to K when P is all zero; rescales when camera_info describes a
/// different size than the image. Throws FrameInputError as validateCameraInfo() does.
mc_flow::Intrinsics intrinsicsFromCameraInfo(const sensor_msgs::CameraInfo& info, int width, int height);

/// @brief Converts and resizes one synchronised frame. Validates the three messages first
/// (message_validation.h), so any header is safe to pass. Depth of a different size than the RGB image is
/// resampled when both have the same aspect ratio. Throws FrameInputError naming the bad value for an
/// unsupported encoding, an inconsistent buffer, a size/aspect mismatch, all-invalid depth or unusable
/// intrinsics. Colour: rgb8 bgr8 rgba8 bgra8 mono8 mono16; depth: 16UC1 (mm, 0 = invalid), 32FC1 (m, NaN/0 =
/// invalid). `max_pixels` bounds each image's pixel count. The downsample factor is
/// mc_flow::chooseDownsample(downsample_request, width) and intensity and depth are downsampled by the core's
/// rule (mc_flow::downsampleFrame, depth neighbours within `depth_range` [m], Config::depth_downsample_range).
FrameInput toFrameInput(const sensor_msgs::Image& rgb, const sensor_msgs::Image& depth,
                        const sensor_msgs::CameraInfo& info, int downsample_request,
                        std::uint64_t max_pixels = mc_flow::kDefaultMaxInputPixels,
                        double depth_range = mc_flow::Config().depth_downsample_range);

/// @brief Camera info of the processing resolution (outputs can be projected with it).
sensor_msgs::CameraInfo processingCameraInfo(const FrameInput& input);

/// @brief The frame for a mc_flow::SequencePipeline at factor 1 (`input` is already at the processing resolution): its
/// intensity and depth (moved out of `input`), intrinsics, its stamp [s] and frame_id (the source), and `input`
/// (without its frame: read it from the pipeline, PairContext::previous_frame) as the frame's extra.
mc_flow::StreamFrame toStreamFrame(FrameInput input);

/// @brief Everything the output builders need besides the Result.
struct PairContext {
  std_msgs::Header header;               ///< stamp of the current frame, input frame_id
  ros::Time previous_stamp;              ///< stamp of the previous frame of the pair
  const FrameInput* previous = nullptr;  ///< the pair's first frame (its colour, header, intrinsics)
  const FrameInput* current = nullptr;   ///< the pair's second frame
  /// The first frame's intensity and depth (points of the scene flow cloud, grey of ~segmentation): the pipeline's
  /// (toStreamFrame moves them there); null: `previous->frame`.
  const mc_flow::RgbdFrame* previous_frame = nullptr;
  const mc_flow::RgbdFrame* firstFrame() const {
    return previous_frame ? previous_frame : previous ? &previous->frame : nullptr;
  }
  double solve_time_ms = 0;
  /// Each segment's motion relative to the static world (SequenceStep::world_velocities); null: unknown.
  const std::vector<mc_flow::WorldVelocity>* world = nullptr;
  /// @brief Seconds between the frames (> 0).
  double interval() const { return (header.stamp - previous_stamp).toSec(); }
};

/// @brief The context of a solved `step` whose frames carry their FrameInput as the extra (toStreamFrame): the current
/// frame's header, both frames, the world's velocities (valid while the step's are) and `solve_ms`.
PairContext pairContext(const mc_flow::SequenceStep& step, double solve_ms);

/// @brief ~segments: ids, twists [m/s, rad/s], interval transforms, support, centroid, colour.
mc_flow::SegmentArray makeSegmentArray(const mc_flow::Result& result, const PairContext& pair);

/// @brief ~odom: the camera's odometry (mc_flow::Odometry, the camera's optical frame in its first pose) as the
/// odometry of the frame `child_frame` mounted at `base_from_camera` (identity: the camera itself), so that the base
/// starts at the identity of `odom_frame`: pose = M C M^-1. Pose covariance in odom_frame (x y z, rotation about x y
/// z), twist and its covariance in child_frame (REP 105, nav_msgs/Odometry's conventions).
nav_msgs::Odometry makeOdometry(const mc_flow::Odometry& odometry, const ros::Time& stamp,
                                const std::string& odom_frame, const std::string& child_frame,
                                const Eigen::Isometry3d& base_from_camera);

/// @brief ~camera_path (for display): the camera's poses `poses` (mc_flow::Odometry::pose of each pair, oldest first)
/// expressed in its latest one, in `header`'s frame (the colour camera's optical frame now): where the camera came
/// from, drawn in rviz without any TF. ~odom is the odometry itself.
nav_msgs::Path makeCameraPath(const std::deque<Eigen::Matrix4d>& poses, const std_msgs::Header& header);

/// @brief ~moving_mask: mono8, 255 = a pixel of a segment that moves relative to the static world.
/// The image and cloud outputs take an optional MessagePool (message_pool.h): the message then comes from the pool and
/// is filled in place (the same bytes as a new one), so a stream at one size allocates nothing per pair.
using ImagePool = MessagePool<sensor_msgs::Image>;
using CloudPool = MessagePool<sensor_msgs::PointCloud2>;

sensor_msgs::ImagePtr makeMovingMaskImage(const mc_flow::Result& result,
                                          const std::vector<mc_flow::WorldVelocity>& world, const PairContext& pair,
                                          ImagePool* pool = nullptr);

/// @brief ~soft_labels: one 32FC<n> image, n = segments + 1; channel i is segment i of ~segments, the
/// last channel the outlier label; values exactly as the solver produced them (lossless, sum to 1).
sensor_msgs::ImagePtr makeSoftLabelsImage(const mc_flow::Result& result, const PairContext& pair,
                                          ImagePool* pool = nullptr);
/// @brief How many of `depth`'s values mc_flow::isValidDepth accepts (the count toFrameInput checks), in a loop that
/// vectorises.
int countValidDepth(const std::vector<float>& depth);

/// @brief Pixels [begin, end) of `labels`' planes interleaved per pixel into `out` (labels.count floats per pixel,
/// pixel p at out + p * count: ~soft_labels' data). Writes exactly those floats, so that threads may fill disjoint
/// ranges of one buffer; 2-8 planes 8 pixels at a time with AVX2 where the CPU has it.
void interleaveSoftLabels(const mc_flow::SoftLabels& labels, std::size_t begin, std::size_t end, float* out);
/// @brief ~labels: mono16 argmax with persistent ids (0 = outlier or no depth).
sensor_msgs::ImagePtr makeLabelsImage(const mc_flow::Result& result, const PairContext& pair,
                                      ImagePool* pool = nullptr);
/// @brief ~occlusion: mono8, 255 = occluded (or out of view) in the current frame.
sensor_msgs::ImagePtr makeOcclusionImage(const mc_flow::Result& result, const PairContext& pair,
                                         ImagePool* pool = nullptr);
/// @brief ~segmentation: rgb8 message of a segmentationPicture (CV_8UC3, below) with the pair's header.
sensor_msgs::ImagePtr makeSegmentationImage(const cv::Mat& picture, const PairContext& pair, ImagePool* pool = nullptr);
/// @brief ~segmentation rendered straight into the message (from `pool` when given): the same bytes as
/// makeSegmentationImage(segmentationPicture(result, pair, blend), pair) without the picture's copies.
sensor_msgs::ImagePtr makeSegmentationImage(const mc_flow::Result& result, const PairContext& pair, double blend,
                                            ImagePool* pool = nullptr);

/// @brief How the ~scene_flow cloud's rgb field is filled.
enum class CloudColour { Segment, Image };

/// @brief ~scene_flow: organized cloud (processing resolution) of the previous frame's points.
/// Fields: x y z [m] (float32, the point at the previous stamp), rgb (float32-packed), vx vy vz [m over
/// the interval] (float32), label (uint32 persistent id, 0 = outlier/no depth), occluded (uint8, 1 =
/// occluded in the current frame). Invalid points have NaN in x y z vx vy vz.
sensor_msgs::PointCloud2Ptr makeSceneFlowCloud(const mc_flow::Result& result, const PairContext& pair,
                                               CloudColour colour = CloudColour::Segment, CloudPool* pool = nullptr);

/// @brief Which of the three large outputs makeImageOutputs builds, and how (the make* functions' arguments).
struct ImageOutputRequest {
  bool soft_labels = false, segmentation = false, scene_flow = false;
  double segmentation_blend = 0.5;
  CloudColour cloud_colour = CloudColour::Segment;
  ImagePool* soft_labels_pool = nullptr;
  ImagePool* segmentation_pool = nullptr;
  CloudPool* cloud_pool = nullptr;
};
/// @brief The messages of makeImageOutputs; null where not requested.
struct ImageOutputs {
  sensor_msgs::ImagePtr soft_labels, segmentation;
  sensor_msgs::PointCloud2Ptr scene_flow;
};
/// @brief ~soft_labels, ~segmentation and ~scene_flow as requested, the same bytes as makeSoftLabelsImage,
/// makeSegmentationImage(result, pair, blend) and makeSceneFlowCloud, their rows filled in one parallel region: each
/// region wakes the OpenMP threads, which under OMP_WAIT_POLICY=passive cost about 0.15 ms on a 2-core VM (docs/
/// PERFORMANCE.md, "Nodelet overhead per pair"). ~segmentation needs the soft labels.
ImageOutputs makeImageOutputs(const mc_flow::Result& result, const PairContext& pair,
                              const ImageOutputRequest& request);

/// @brief ~motion_markers: per segment an arrow from its centroid along its centroid's velocity
/// (length = speed x `seconds_ahead`) and a text with id and speed; starts with a DELETEALL marker.
visualization_msgs::MarkerArray makeMotionMarkers(const mc_flow::Result& result, const PairContext& pair,
                                                  double seconds_ahead = 1.0);

/// @brief The TF transforms of ~publish_tf: per segment that has a track, child frame `prefix` + id, origin at
/// its centroid at the current stamp, orientation its rotation accumulated since it appeared (`tracks`:
/// SequencePipeline::tracks()); parent and stamp from the pair's header.
std::vector<geometry_msgs::TransformStamped> makeSegmentTransforms(const mc_flow::Result& result,
                                                                   const std::map<int, mc_flow::SegmentTrack>& tracks,
                                                                   const PairContext& pair, const std::string& prefix);

/// @brief Velocity of a segment's centroid [m/s] over the pair interval.
Eigen::Vector3d centroidVelocity(const mc_flow::Segment& segment, double interval);

/// @brief The segmentation picture (CV_8UC3 RGB): the previous frame's colour blended with the soft-label-weighted
/// segment colours (`blend` = weight of the segment colours, 0..1); for the image message and save_dir.
cv::Mat segmentationPicture(const mc_flow::Result& result, const PairContext& pair, double blend);

}  // namespace mc_flow_ros
