#include "mmrl/decider.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>


namespace mmrl {

void MotionSource::set_state(MotionState&, const float*) const {
  throw std::invalid_argument("set_state: this motion source shows database frames (set its frame instead)");
}

const float* candidate_raw_trajectory(const Database& db, const Candidate& c, float* scratch) {
  if (c.row >= 0) return &db.features[static_cast<size_t>(c.row) * kFeatureDim + kPoseDim];
  trajectory_denormalize(db, c.features + kPoseDim, scratch);
  return scratch;
}

Decider::Decider(const Database& db, float action_limit_std) {
  if (action_limit_std > 0) {
    trajectory_action_box(db, action_limit_std, low_, high_);
  } else {
    std::fill(low_, low_ + kTrajectoryDim, -INFINITY);
    std::fill(high_, high_ + kTrajectoryDim, INFINITY);
  }
}

void Decider::set_action_box(const float* low, const float* high) {
  for (int k = 0; k < kTrajectoryDim; ++k)
    if (!(low[k] <= high[k])) throw std::invalid_argument("action box: low must be <= high in every dimension");
  std::copy(low, low + kTrajectoryDim, low_);
  std::copy(high, high + kTrajectoryDim, high_);
}

Decision Decider::decide(const MotionSource& source, MotionState& s, const float* action,
                         const DecisionRules& rules) const {
  const Candidate now = source.current(s);
  float query[kFeatureDim];
  for (int k = 0; k < kPoseDim; ++k) query[k] = now.features[k];
  for (int k = 0; k < kTrajectoryDim; ++k) query[kPoseDim + k] = std::min(high_[k], std::max(low_[k], action[k]));
  Decision d = source.decide(s, query, rules);
  d.transition_cost = rules.transition_cost;
  d.pose_jump = 0;
  if (d.transition) {
    const float* a = now.features;
    const float* b = source.chosen(s, d).features;
    for (int k = 0; k < kPoseDim; ++k) d.pose_jump += (a[k] - b[k]) * (a[k] - b[k]);
  }
  return d;
}

}  // namespace mmrl
