/**
 * @file benchmark.h
 * @brief The real RGB-D pairs of the shared set as PNG files (OpenCV decodes them): the loader of `mcflow bench-real`
 * and `mcflow export-real`. What is done with a pair (preparing, solving, scoring, the table) is
 * mc_flow/eval/real_pairs.h, shared with `mcflow_bench --real`.
 */
#pragma once

#include <string>

#include "mc_flow/core/config.h"
#include "mc_flow/eval/real_pairs.h"

namespace mc_flow {
namespace io {

/// @brief Loads `data_dir`/`name`/{color,depth}{0,1}.png (16-bit depth, 5000 units per metre) and prepares it
/// (prepareRealPair: depth cleaned, halved `halvings` times; 1 = 320x240, the paper's resolution). Throws
/// InputError naming the missing file.
RealPair loadRealPair(const std::string& data_dir, const std::string& name, int halvings, const Config& config);

}  // namespace io
}  // namespace mc_flow
