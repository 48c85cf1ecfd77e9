#include "mmrl/decider.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>


namespace mmrl {

void MotionSource::set_state(MotionState&, const float*) const {
  throw std::invalid_argument("set_state: this motion source shows database frames (set its frame instead)");
}

Decider::Decider(const Database& db, float action_limit_std) {
  if (action_limit_std > 0) {
    trajectory_action_box(db, action_limit_std, low_, high_);
  } else {
    std::fill(low_, low_ + kTrajectoryDim, -INFINITY);
    std::fill(high_, high_ + kTrajectoryDim, INFINITY);
  }
  const auto scale = db.normalization.column_scale();
  for (int k = 0; k < kPoseDim; ++k) {
    pose_mean_[k] = db.normalization.mean[k];
    pose_scale_[k] = scale[k];
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
    if (rules.anchor) anchor(a, b, d);
  }
  return d;
}

void Decider::anchor(const float* now, const float* chosen, Decision& d) const {
  // Both feet planted in both poses (foot_planted, features.hpp): the root moves by minus their
  // mean offset (x, z), so their mean stays where it is. A transition with only one foot planted
  // in both poses is left alone: anchoring it measured no stiller (docs/arrive.md).
  auto raw = [this](const float* f, int k) { return f[k] * pose_scale_[k] + pose_mean_[k]; };
  auto planted = [&](const float* f, int side) {
    const float v[3] = {raw(f, 6 + 3 * side), raw(f, 7 + 3 * side), raw(f, 8 + 3 * side)};
    return foot_planted(v);
  };
  float dx = 0, dz = 0;
  int n = 0;
  for (int side = 0; side < 2; ++side) {
    if (!planted(now, side) || !planted(chosen, side)) continue;
    dx += raw(chosen, 3 * side) - raw(now, 3 * side);
    dz += raw(chosen, 3 * side + 2) - raw(now, 3 * side + 2);
    ++n;
  }
  if (n < 2 || !std::isfinite(dx) || !std::isfinite(dz)) return;  // a zero feature weight: no positions
  d.anchor[0] = -dx / static_cast<float>(n);
  d.anchor[1] = -dz / static_cast<float>(n);
}

}  // namespace mmrl
