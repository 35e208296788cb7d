// One RGB-D stream: preprocessing, pairing and resets, the warm start and the segment tracks.
#include "mc_flow/core/sequence.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "mc_flow/core/error.h"
#include "mc_flow/core/label_optimization.h"
#include "mc_flow/core/pyramid.h"
#include "mc_flow/core/solve_backend.h"
#include "mc_flow/core/warm_start.h"

namespace mc_flow {

namespace {

bool isPowerOfTwo(int v) { return v > 0 && (v & (v - 1)) == 0; }

}  // namespace

int chooseDownsample(int requested, int width) {
  if (requested < 0 || (requested > 0 && !isPowerOfTwo(requested)))
    throw ConfigError("downsample = " + std::to_string(requested) +
                      " is invalid: must be 0 (automatic) or a power of two");
  if (requested > 0) return requested;
  int best = 1;
  for (int factor = 2; factor <= 16; factor *= 2)
    if (std::abs(width / factor - 320) < std::abs(width / best - 320)) best = factor;
  return best;
}

RgbdFrame downsampleFrame(RgbdFrame frame, int factor, double depth_range) {
  if (!isPowerOfTwo(factor))
    throw ConfigError("downsample factor " + std::to_string(factor) + " is not a power of two");
  RgbdFrame out = std::move(frame);
  // The pyramid's halving expects 0 for invalid depth (NaN never enters it): NaN, infinities and negatives
  // become 0 (written without isfinite, so that the loop vectorises).
  for (float& z : out.depth.data) z = (z >= 0.f && z <= std::numeric_limits<float>::max()) ? z : 0.f;
  for (int f = factor; f > 1; f /= 2) {
    out.intensity = downsampleIntensity(out.intensity);
    out.depth = downsampleDepth(out.depth, depth_range);
  }
  return out;
}

std::string toString(SequenceStep::Outcome outcome) {
  switch (outcome) {
    case SequenceStep::Outcome::Solved: return "solved";
    case SequenceStep::Outcome::Started: return "started";
    case SequenceStep::Outcome::RepeatedStamp: return "repeated_stamp";
    case SequenceStep::Outcome::PairFailed: return "pair_failed";
  }
  return "unknown";
}

SequencePipeline::SequencePipeline(const Config& config, int downsample, double max_pair_interval,
                                   SolveBackendFactory make_backend)
    : config_(config),
      downsample_request_(downsample),
      max_pair_interval_(max_pair_interval),
      make_backend_(std::move(make_backend)) {
  chooseDownsample(downsample, 320);  // validates the request
  if (!(max_pair_interval > 0) || !std::isfinite(max_pair_interval))
    throw ConfigError("max_pair_interval = " + std::to_string(max_pair_interval) +
                      " s is invalid: must be finite and > 0");
  solver_ = makeSolver(config_, &backend_unavailable_);
}

std::unique_ptr<Solver> SequencePipeline::makeSolver(const Config& config, std::string* unavailable,
                                                     const std::string& why) {
  config.validate();  // before a backend is made, as Solver(config) does
  auto make = [this, &config](Backend requested, std::string* note) {
    return make_backend_ ? make_backend_(requested, note) : makeSolveBackend(requested, note, config.cuda_device);
  };
  std::string note, failed;
  std::unique_ptr<SolveBackend> backend;
  Config solver_config = config;
  try {
    backend = make(config.backend, &note);
  } catch (const BackendError& e) {
    // A node that processes nothing helps no one: the CPU solves the stream, and the reason (no GPU, a cuda_device
    // that does not exist) reaches the caller's one warning through backendUnavailable() and Result::backend_note.
    if (config.backend == Backend::Cpu) throw;
    failed = e.what();
    solver_config.backend = Backend::Cpu;
    backend = make(Backend::Cpu, &note);
    note = "cpu (fallback: " + failed + ")";
  }
  if (unavailable) *unavailable = failed;
  if (!why.empty()) note = why;
  auto solver = std::make_unique<Solver>(solver_config, std::move(backend), note);
  solver->setOutputs(outputs_);
  return solver;
}

void SequencePipeline::setOutputs(const OutputSelection& selection) {
  outputs_ = selection;
  solver_->setOutputs(selection);
}

void SequencePipeline::setConfig(const Config& config) {
  std::string unavailable;
  solver_ = makeSolver(config, &unavailable);
  config_ = config;
  backend_unavailable_ = std::move(unavailable);
}

void SequencePipeline::reset() {
  pair_first_.reset();
  previous_frame_.reset();
  last_result_.reset();
  tracks_.clear();
}

PreparedFrame SequencePipeline::prepare(StreamFrame frame) const {
  frame.K.validate();
  frame.frame.validate("frame");
  PreparedFrame out;
  out.input_width = frame.frame.width();
  out.input_height = frame.frame.height();
  out.downsample = chooseDownsample(downsample_request_, out.input_width);
  const int w = out.input_width / out.downsample, h = out.input_height / out.downsample;
  if (w < 16 || h < 16)
    throw InputError("processing size " + imageSizeText(w, h) + " (input " +
                     imageSizeText(out.input_width, out.input_height) + " / downsample " +
                     std::to_string(out.downsample) + ") is too small: at least 16x16");
  out.frame = out.downsample == 1
                  ? std::move(frame.frame)
                  : downsampleFrame(std::move(frame.frame), out.downsample, config_.depth_downsample_range);
  out.K = frame.K.scaled(1.0 / out.downsample);
  out.stamp = frame.stamp;
  out.source = std::move(frame.source);
  out.extra = std::move(frame.extra);
  out.camera_pose_prior = frame.camera_pose_prior;
  return out;
}

SequenceStep SequencePipeline::push(StreamFrame input) {
  PreparedFrame frame = prepare(std::move(input));
  SequenceStep step;
  if (previous_frame_) {
    const PreparedFrame& previous = *previous_frame_;
    const double dt = frame.stamp - previous.stamp;
    if (dt == 0.0) {
      step.outcome = SequenceStep::Outcome::RepeatedStamp;
      return step;
    }
    if (dt < 0.0) {
      step.reset_key = "back";
      step.reset_reason = "the stamp went back by " + std::to_string(-dt) + " s (stream reset or bag loop)";
    } else if (dt > max_pair_interval_) {
      step.reset_key = "gap";
      step.reset_reason = "a gap of " + std::to_string(dt) + " s exceeds max_pair_interval " +
                          std::to_string(max_pair_interval_) + " s";
    } else if (frame.source != previous.source || !frame.frame.intensity.sameSize(previous.frame.intensity)) {
      step.reset_key = "input";
      step.reset_reason = "the input changed from '" + previous.source + "' " +
                          imageSizeText(previous.input_width, previous.input_height) + " to '" + frame.source + "' " +
                          imageSizeText(frame.input_width, frame.input_height);
    }
    if (!step.reset_key.empty()) {
      reset();
      ++resets_;
    }
  }
  if (!previous_frame_) {
    previous_frame_ = std::make_unique<PreparedFrame>(std::move(frame));
    step.outcome = SequenceStep::Outcome::Started;
    return step;
  }

  const PreparedFrame& first = *previous_frame_;
  Result result;
  try {
    // The camera's motion from the first frame to the second by the other source: the static world's prior.
    std::optional<Eigen::Matrix4d> camera_motion;
    if (first.camera_pose_prior && frame.camera_pose_prior)
      camera_motion = Eigen::Matrix4d(first.camera_pose_prior->inverse() * *frame.camera_pose_prior);
    if (camera_motion) {
      result = solver_->solve(first.frame, frame.frame, first.K, last_result_.get(), *camera_motion);
    } else if (last_result_) {
      result = solver_->solve(first.frame, frame.frame, first.K, *last_result_);
    } else {
      result = solver_->solve(first.frame, frame.frame, first.K);
    }
    // No previous result (the first pair, after a reset or a failed pair): the solver numbered the segments 1..m;
    // they are moved above every id handed out so far, so no earlier segment's id (track, TF frame) is reused.
    if (!last_result_) offsetSegmentIds(result, next_id_);
  } catch (const BackendError& e) {
    // The GPU failed at run time: the following pairs run on the CPU.
    step.backend_fallback = std::string(e.what());
    const std::string failed = solver_->backendName();
    step.problem = "the " + failed + " backend failed: " + e.what();
    ++backend_fallbacks_;
    Config cpu = config_;
    cpu.backend = Backend::Cpu;
    solver_ = makeSolver(cpu, nullptr, "cpu (fallback: the " + failed + " backend failed)");
    config_ = cpu;
  } catch (const InputError& e) {
    step.problem = e.what();
  } catch (const ConfigError& e) {
    // Parameters that do not fit this input (e.g. processing_level deeper than its pyramid).
    step.problem = e.what();
  }
  if (!step.problem.empty()) {
    // The sequence goes on from this frame, without a prior (the last result does not end at it).
    step.outcome = SequenceStep::Outcome::PairFailed;
    previous_frame_ = std::make_unique<PreparedFrame>(std::move(frame));
    last_result_.reset();
    return step;
  }
  pair_first_ = std::move(previous_frame_);
  previous_frame_ = std::make_unique<PreparedFrame>(std::move(frame));
  if (last_result_) solver_->recycle(std::move(*last_result_));  // its image memory serves the next pair
  last_result_ = std::make_unique<Result>(std::move(result));
  next_id_ = std::max(next_id_, last_result_->next_id);
  updateTracks(*last_result_);
  const double interval = previous_frame_->stamp - pair_first_->stamp;
  updateOdometry(*last_result_, interval, previous_frame_->stamp);
  for (const Segment& s : last_result_->segments) {
    step.world_velocities.push_back(
        worldVelocity(s, s.covariance, last_result_->world, last_result_->world.contains(s.id), interval, config_));
  }
  step.outcome = SequenceStep::Outcome::Solved;
  step.first = pair_first_.get();
  step.second = previous_frame_.get();
  step.result = last_result_.get();
  step.pair_index = pairs_solved_++;
  return step;
}

void SequencePipeline::updateOdometry(const Result& result, double interval_s, double stamp) {
  // The camera moved by the inverse of the world's motion: C2 = C1 exp(-world.twist).
  const Eigen::Matrix4d step = se3Exp(-result.world.twist);
  // A right perturbation carried through the step: d2 = Ad(step^-1) d1 + e, e the step's own uncertainty (log of the
  // inverse is minus the twist, so the world fit's covariance is the step's).
  const Matrix6d adjoint = se3Adjoint(step.inverse());
  odometry_.pose = odometry_.pose * step;
  odometry_.pose_covariance = adjoint * odometry_.pose_covariance * adjoint.transpose() + result.world.covariance;
  odometry_.velocity = -result.world.twist / interval_s;
  odometry_.velocity_covariance = result.world.covariance / (interval_s * interval_s);
  odometry_.stamp = stamp;
  ++odometry_.pairs;
}

void SequencePipeline::updateTracks(const Result& result) {
  std::map<int, SegmentTrack> next;
  for (const Segment& s : result.segments) {
    SegmentTrack track;
    const auto known = tracks_.find(s.id);
    if (known != tracks_.end()) {
      track = known->second;
    } else {
      track.first_pair = pairs_solved_;
    }
    track.pose = s.transform * track.pose;
    track.origin = s.transform.topLeftCorner<3, 3>() * s.centroid + s.transform.topRightCorner<3, 1>();
    track.last_pair = pairs_solved_;
    next[s.id] = track;
  }
  tracks_ = std::move(next);
}

void movingMaskInto(const Result& result, const std::vector<WorldVelocity>& world, std::uint8_t* mask) {
  if (world.size() != result.segments.size())
    throw InputError("moving mask: " + std::to_string(world.size()) + " world velocities for " +
                     std::to_string(result.segments.size()) + " segments");
  // 255 or 0 per id up to the largest segment id (a look-up per pixel instead of a search: the nodelet makes this mask
  // for every pair); ids beyond it, negative ones and 0 are no segment's.
  int largest = 0;
  for (const Segment& s : result.segments) largest = std::max(largest, s.id);
  std::vector<std::uint8_t> value_of(std::size_t(largest) + 1, 0);
  for (std::size_t i = 0; i < world.size(); ++i)
    if (world[i].moving && result.segments[i].id > 0) value_of[std::size_t(result.segments[i].id)] = 255;
  const std::int32_t* ids = result.labels.data.data();
  const std::size_t count = result.labels.data.size(), table = value_of.size();
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t id = std::size_t(std::uint32_t(ids[k]));  // negative ids become huge: outside the table
    mask[k] = id < table ? value_of[id] : 0;
  }
}

ImageU8 movingMask(const Result& result, const std::vector<WorldVelocity>& world) {
  ImageU8 mask(result.labels.width, result.labels.height, 1, 0);
  movingMaskInto(result, world, mask.data.data());
  return mask;
}

}  // namespace mc_flow
