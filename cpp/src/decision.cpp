#include "mmrl/decision.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace mmrl {

void check_frames_per_step(int frames_per_step) {
  if (frames_per_step < 1 || frames_per_step > kMaxFramesPerStep)
    throw std::invalid_argument("frames_per_step must be between 1 and " + std::to_string(kMaxFramesPerStep) +
                                ", got " + std::to_string(frames_per_step));
}

ClipCostFilter::ClipCostFilter(const Database& db, std::vector<float> costs, const char* option)
    : costs_(std::move(costs)) {
  if (costs_.empty()) return;
  if (static_cast<int64_t>(costs_.size()) != db.num_clips())
    throw std::invalid_argument(std::string(option) + ": expected one cost per clip (" +
                                std::to_string(db.num_clips()) + "), got " + std::to_string(costs_.size()));
  for (size_t c = 0; c < costs_.size(); ++c)
    if (!(costs_[c] >= 0.0f))
      throw std::invalid_argument(std::string(option) + ": the cost of clip " + std::to_string(c) +
                                  " must be >= 0 (inf: never play it), got " + std::to_string(costs_[c]));
  frame_clip_ = db.frame_clip.data();
}

int shortlist_queries(const Database& db, const float* query, const Shortlist& shortlist, float* out) {
  std::copy(query, query + kFeatureDim, out);
  float raw[kTrajectoryDim], turned[kTrajectoryDim];
  trajectory_denormalize(db, query + kPoseDim, raw);
  int n = 1;
  for (int m = 1; m <= shortlist.fan; ++m)
    for (int side : {1, -1}) {
      const float a = static_cast<float>(side * m) * shortlist.fan_step;
      const float c = std::cos(a), s = std::sin(a);
      for (int k = 0; k < kTrajectoryDim; k += 2) {  // (x, z) pairs: positions and directions
        turned[k] = c * raw[k] + s * raw[k + 1];
        turned[k + 1] = -s * raw[k] + c * raw[k + 1];
      }
      float* q = out + static_cast<size_t>(n) * kFeatureDim;
      std::copy(query, query + kPoseDim, q);
      trajectory_normalize(db, turned, q + kPoseDim);
      ++n;
    }
  // Escapes: stand, back, left, right (X left, Z forward), facing ahead at every sample.
  static constexpr float kDirections[kMaxEscapes][2] = {{0, 0}, {0, -1}, {1, 0}, {-1, 0}};
  for (int e = 0; e < std::min(shortlist.escapes, kMaxEscapes); ++e) {
    for (int h = 0; h < 3; ++h) {
      const float d = kEscapeSpeed * static_cast<float>(kTrajectoryOffsets[h]) / db.fps;
      turned[4 * h] = kDirections[e][0] * d;
      turned[4 * h + 1] = kDirections[e][1] * d;
      turned[4 * h + 2] = 0.0f;
      turned[4 * h + 3] = 1.0f;
    }
    float* q = out + static_cast<size_t>(n) * kFeatureDim;
    std::copy(query, query + kPoseDim, q);
    trajectory_normalize(db, turned, q + kPoseDim);
    ++n;
  }
  return n;
}

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
