#include "mmrl/controller.hpp"

#include <cmath>

namespace mmrl {

void trajectory_action_box(const Database& db, float limit_std, float* low, float* high) {
  double sum[kTrajectoryDim] = {}, sq[kTrajectoryDim] = {};
  int64_t n = 0;
  for (int64_t i = 0; i < db.num_frames; ++i) {
    if (!db.valid[i]) continue;
    const float* t = &db.normalized[static_cast<size_t>(i) * kFeatureDim + kPoseDim];
    for (int k = 0; k < kTrajectoryDim; ++k) {
      sum[k] += t[k];
      sq[k] += static_cast<double>(t[k]) * t[k];
    }
    ++n;
  }
  for (int k = 0; k < kTrajectoryDim; ++k) {
    const double mean = n ? sum[k] / n : 0.0;
    const double sd = n ? std::sqrt(std::max(0.0, sq[k] / n - mean * mean)) : 1.0;
    low[k] = static_cast<float>(mean - limit_std * sd);
    high[k] = static_cast<float>(mean + limit_std * sd);
  }
}

}  // namespace mmrl
