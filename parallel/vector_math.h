// The vectorisable elementary functions of parallel/internal/vmath.h and exp.h that other layers
// call from their lane kernels (engine/landmark_batch.cc, engine/motion_batch.h, the filter's
// trajectory recorder): sine and cosine, atan2, log, exp of a non-positive argument, the
// explicit multiply-add and the branch-free select. Their contracts (domains, error bounds, same
// bits in scalar and vector loops, on every machine) are those headers'.
// Thread safety: pure functions. Costs: O(1), no allocation.
#pragma once

#include "parallel/internal/exp.h"
#include "parallel/internal/vmath.h"

namespace fastslam::parallel {

using internal::arctan2;
using internal::exp_nonpositive;
using internal::kSinCosMaxArg;
using internal::kSinCosSmallArg;
using internal::log_positive;
using internal::madd;
using internal::select;
using internal::sincos;
using internal::sincos_in_domain;
using internal::sincos_small;

}  // namespace fastslam::parallel
