// The backend-fault test hook: a forwarding SolveBackend that fails once, in the middle of a chosen solve.
#include "mc_flow/testing/fault_injection.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <thread>
#include <utility>

#include "mc_flow/core/error.h"
#include "mc_flow/core/solve_backend.h"

namespace mc_flow {

namespace {

// Every operation forwards to the wrapped backend; a stage operation first calls strike(name). The cheap
// queries (kind, labelCount, validCounts) are not stages: they never reach the device.
class FaultInjectingBackend final : public SolveBackend {
 public:
  FaultInjectingBackend(std::unique_ptr<SolveBackend> inner, BackendFault fault)
      : inner_(std::move(inner)), fault_(std::move(fault)) {}

  Backend kind() const override { return inner_->kind(); }
  void activate() override { inner_->activate(); }

  void buildPyramids(const RgbdFrame& frame1, const RgbdFrame& frame2, const Intrinsics& K, int levels,
                     const Config& config) override {
    ++solves_;
    strike("buildPyramids");
    inner_->buildPyramids(frame1, frame2, K, levels, config);
  }
  const ImageF& framePoints(int level) override {
    strike("framePoints");
    return inner_->framePoints(level);
  }
  const std::vector<int>& validCounts() const override { return inner_->validCounts(); }
  std::vector<Eigen::Vector3f> kmeansCentres(int level, int k, int max_iterations, double tolerance_m,
                                             unsigned seed) override {
    strike("kmeansCentres");
    return inner_->kmeansCentres(level, k, max_iterations, tolerance_m, seed);
  }
  CarriedSegments carrySegments(const Result& previous, const ImageF& frame1_depth, int label_level,
                                const Config& config) override {
    strike("carrySegments");
    return inner_->carrySegments(previous, frame1_depth, label_level, config);
  }
  void initialiseLabels(int level, const ImageI32& hard, int motion_labels) override {
    strike("initialiseLabels");
    inner_->initialiseLabels(level, hard, motion_labels);
  }
  void initialiseLabelsFromCentres(int level, const std::vector<Eigen::Vector3f>& centres) override {
    strike("initialiseLabelsFromCentres");
    inner_->initialiseLabelsFromCentres(level, centres);
  }
  void holdCarriedLabels(int carried_labels) override {
    strike("holdCarriedLabels");
    inner_->holdCarriedLabels(carried_labels);
  }
  void moveLabels(int level) override {
    strike("moveLabels");
    inner_->moveLabels(level);
  }
  MotionAccumulator& motionAccumulator(int level, MotionLabels which, bool use_occlusion,
                                       const Config& config) override {
    strike("motionAccumulator");
    return inner_->motionAccumulator(level, which, use_occlusion, config);
  }
  void updateOcclusion(const std::vector<Vector6d>& twists, const Config& config) override {
    strike("updateOcclusion");
    inner_->updateOcclusion(twists, config);
  }
  LabelStepStats labelStep(const std::vector<Vector6d>& twists, bool use_occlusion, int iterations, double tolerance,
                           const Config& config) override {
    strike("labelStep");
    return inner_->labelStep(twists, use_occlusion, iterations, tolerance, config);
  }
  SoftLabels downloadLabels() override {
    strike("downloadLabels");
    return inner_->downloadLabels();
  }
  void outputs(const std::vector<Vector6d>& twists, const Config& config, const OutputSelection& selection,
               Result& result) override {
    strike("outputs");
    inner_->outputs(twists, config, selection, result);
  }

  int labelCount() const override { return inner_->labelCount(); }
  std::vector<double> supports() override {
    strike("supports");
    return inner_->supports();
  }
  void remap(const std::vector<int>& target, int new_count) override {
    strike("remap");
    inner_->remap(target, new_count);
  }
  std::vector<LabelMoments> ownedMoments() override {
    strike("ownedMoments");
    return inner_->ownedMoments();
  }
  CutTrial trialCuts(const std::vector<LabelCut>& cuts, const std::vector<Vector6d>& twists, bool use_occlusion,
                     const Config& config) override {
    strike("trialCuts");
    return inner_->trialCuts(cuts, twists, use_occlusion, config);
  }
  void applyCuts(const std::vector<LabelCut>& cuts, bool use_occlusion, const Config& config) override {
    strike("applyCuts");
    inner_->applyCuts(cuts, use_occlusion, config);
  }
  LabelCostModel costModel(const std::vector<Vector6d>& twists, bool use_occlusion, const Config& config) override {
    strike("costModel");
    return inner_->costModel(twists, use_occlusion, config);
  }
  std::vector<LabelCostModel> costModels(const std::vector<std::vector<Vector6d>>& twist_sets, bool use_occlusion,
                                         const Config& config) override {
    strike("costModels");
    return inner_->costModels(twist_sets, use_occlusion, config);
  }
  bool refitUnionsWhereTheSumsAre(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& groups,
                                  const std::vector<int>& batches, const std::vector<Vector6d>& starts, int iterations,
                                  bool use_occlusion, const Config& config, std::vector<UnionFit>& fits) override {
    strike("refitUnionsWhereTheSumsAre");
    return inner_->refitUnionsWhereTheSumsAre(twists, groups, batches, starts, iterations, use_occlusion, config, fits);
  }
  bool refitPairsWhereTheSumsAre(const std::vector<Vector6d>& twists, const std::vector<std::vector<int>>& pairs,
                                 const std::vector<int>& batches, const std::vector<double>& own_cost, int iterations,
                                 bool use_occlusion, const Config& config, std::vector<UnionFit>& fits) override {
    strike("refitPairsWhereTheSumsAre");
    return inner_->refitPairsWhereTheSumsAre(twists, pairs, batches, own_cost, iterations, use_occlusion, config, fits);
  }

 private:
  void strike(const char* stage) {
    if (struck_ || solves_ != fault_.solve || fault_.stage != stage) return;
    struck_ = true;
    if (fault_.action) {
      fault_.action(stage);
      return;
    }
    throw BackendError("injected fault in stage " + std::string(stage) + " of solve " + std::to_string(solves_) +
                       " of the " + toString(inner_->kind()) + " backend (test hook)");
  }

  std::unique_ptr<SolveBackend> inner_;
  BackendFault fault_;
  long solves_ = 0;
  bool struck_ = false;
};

}  // namespace

const std::vector<std::string>& backendFaultStages() {
  static const std::vector<std::string> stages{"buildPyramids",
                                               "framePoints",
                                               "kmeansCentres",
                                               "carrySegments",
                                               "initialiseLabels",
                                               "initialiseLabelsFromCentres",
                                               "holdCarriedLabels",
                                               "moveLabels",
                                               "motionAccumulator",
                                               "updateOcclusion",
                                               "labelStep",
                                               "downloadLabels",
                                               "outputs",
                                               "supports",
                                               "remap",
                                               "ownedMoments",
                                               "trialCuts",
                                               "applyCuts",
                                               "costModel",
                                               "costModels",
                                               "refitUnionsWhereTheSumsAre",
                                               "refitPairsWhereTheSumsAre"};
  return stages;
}

namespace {

// Empty when the fault can be injected, else why not.
std::string faultProblem(const BackendFault& fault) {
  if (fault.solve < 1) return "solve " + std::to_string(fault.solve) + " is invalid: solves count from 1";
  const std::vector<std::string>& stages = backendFaultStages();
  if (std::find(stages.begin(), stages.end(), fault.stage) != stages.end()) return "";
  std::string names;
  for (const std::string& s : stages) names += (names.empty() ? "" : ", ") + s;
  return "unknown stage '" + fault.stage + "' (stages: " + names + ")";
}

}  // namespace

std::unique_ptr<SolveBackend> withBackendFault(std::unique_ptr<SolveBackend> backend, BackendFault fault) {
  if (!backend) throw ConfigError("injected fault: the backend given is null");
  const std::string problem = faultProblem(fault);
  if (!problem.empty()) throw ConfigError("injected fault: " + problem);
  return std::make_unique<FaultInjectingBackend>(std::move(backend), std::move(fault));
}

namespace {

bool allDigits(const std::string& text) {
  return !text.empty() && text.size() <= 9 &&
         std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
}

}  // namespace

BackendFault parseBackendFault(const std::string& text) {
  const std::string bad = "backend fault '" + text +
                          "' is invalid: expected SOLVE, SOLVE:STAGE or SOLVE:STAGE:hold=MS (e.g. 3, 3:labelStep or "
                          "2:labelStep:hold=1500)";
  const std::size_t colon = text.find(':');
  const std::string number = text.substr(0, colon);
  if (!allDigits(number)) throw ConfigError(bad);
  BackendFault fault;
  fault.solve = std::stol(number);
  if (colon != std::string::npos) {
    const std::string rest = text.substr(colon + 1);
    const std::size_t second = rest.find(':');
    fault.stage = rest.substr(0, second);
    if (second != std::string::npos) {
      // A hold instead of a fault: the stage waits, then runs (a solve made slow on purpose, so that a test of what
      // happens while solving does not depend on how fast the machine is).
      const std::string action = rest.substr(second + 1);
      const std::string prefix = "hold=";
      const std::string ms = action.rfind(prefix, 0) == 0 ? action.substr(prefix.size()) : "";
      if (!allDigits(ms)) throw ConfigError(bad + ": '" + action + "' is not hold=MS");
      const long hold_ms = std::stol(ms);
      fault.action = [hold_ms](const std::string&) { std::this_thread::sleep_for(std::chrono::milliseconds(hold_ms)); };
    }
  }
  const std::string problem = faultProblem(fault);
  if (!problem.empty()) throw ConfigError(bad + ": " + problem);
  return fault;
}

SolveBackendFactory faultOnFirstBackend(BackendFault fault, int cuda_device) {
  const std::string problem = faultProblem(fault);
  if (!problem.empty()) throw ConfigError("injected fault: " + problem);
  auto pending = std::make_shared<std::optional<BackendFault>>(std::move(fault));
  return [pending, cuda_device](Backend requested, std::string* note) {
    std::unique_ptr<SolveBackend> backend = makeSolveBackend(requested, note, cuda_device);
    if (!*pending) return backend;
    BackendFault first = std::move(**pending);
    pending->reset();
    return withBackendFault(std::move(backend), std::move(first));
  };
}

}  // namespace mc_flow
