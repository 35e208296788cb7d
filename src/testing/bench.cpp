#include "mc_flow/testing/bench.h"

namespace mc_flow {

std::vector<Regularizer> regularizerChoice(const std::string& text) {
  if (text == "both") return {Regularizer::Quadratic, Regularizer::TotalVariation};
  return {parseRegularizer(text)};
}

}  // namespace mc_flow
