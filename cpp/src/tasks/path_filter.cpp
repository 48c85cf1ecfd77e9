#include "mmrl/tasks/path_filter.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace mmrl {

bool ObstaclePathFilter::prepare(const RuleContext& context) {
  if (!context.obstacles) return false;
  const bool states = context.source.rowless_candidates();
  if (states != states_) set_prices_states(states);
  const ObstacleScene& o = *context.obstacles;
  prepare(*o.field, o.env, o.root, o.moving, o.frame_dt);
  return true;
}

void ObstaclePathFilter::init(const Database& db, int capacity, const PathFilterConfig& config) {
  if (!(config.radius >= 0) || !std::isfinite(config.radius))
    throw std::invalid_argument("path filter: radius must be finite and >= 0");
  if (!(config.cost >= 0)) throw std::invalid_argument("path_cost must be >= 0 (inf: never play a path that hits)");
  if (config.horizon < kPathSampleFrames[0] || config.horizon > kPathSampleFrames[kPathSamples - 1])
    throw std::invalid_argument("path_horizon must be between " + std::to_string(kPathSampleFrames[0]) + " and " +
                                std::to_string(kPathSampleFrames[kPathSamples - 1]) + " frames, got " +
                                std::to_string(config.horizon));
  if (db.path_samples.size() != static_cast<size_t>(db.num_frames) * kPathSamples * 2)
    throw std::invalid_argument("path filter: the database has no path samples (Database::index_clips)");
  if (capacity < 0) throw std::invalid_argument("path filter: capacity must be >= 0");
  db_ = &db;
  paths_ = db.path_samples.data();
  config_ = config;
  capacity_ = capacity;
  samples_ = 0;
  reach_ = 0;
  while (samples_ < kPathSamples && kPathSampleFrames[samples_] <= config.horizon) {
    const float t = static_cast<float>(kPathSampleFrames[samples_]) / static_cast<float>(config.horizon);
    hit_cost_[samples_] = config.cost * (2.0f - t);
    reach_ = std::max(reach_, db.path_reach[samples_]);
    ++samples_;
  }
  cx_.assign(static_cast<size_t>(samples_) * capacity, 0.0f);
  cz_.assign(static_cast<size_t>(samples_) * capacity, 0.0f);
  for (auto* v : {&ocos_, &osin_, &hx_, &hz_, &bound2_}) v->assign(capacity, 0.0f);
  near_.assign(static_cast<size_t>(samples_) * capacity, 0);
  scratch_x_.assign(kPathSampleFrames[kPathSamples - 1], 0.0f);
  scratch_z_.assign(kPathSampleFrames[kPathSamples - 1], 0.0f);
  kept_ = 0;
  prepared_ = false;
}

void ObstaclePathFilter::prepare(const ObstacleField& field, int env, const RootState& root, bool moving,
                                 float frame_dt) {
  // The same obstacles seen from the same root: what the last call prepared still holds.
  const PreparedFor key{&field, env, field.generation(env), root.x, root.z, root.yaw, moving, frame_dt};
  if (prepared_ && key == prepared_for_) return;
  prepared_for_ = key;
  prepared_ = true;
  root_x_ = root.x;
  root_z_ = root.z;
  cos_yaw_ = std::cos(root.yaw);
  sin_yaw_ = std::sin(root.yaw);
  kept_ = 0;
  std::fill(near_count_, near_count_ + kPathSamples, 0);
  if (samples_ == 0) return;
  const int frames = kPathSampleFrames[samples_ - 1];
  const float seconds = static_cast<float>(frames) * frame_dt;
  const float r = config_.radius;
  const int n = std::min(field.count(env), capacity_);
  for (int k = 0; k < n; ++k) {
    const Vec2 c = field.centre(env, k), h = field.half_size(env, k);
    const float extent = std::hypot(h.x(), h.y());
    // An obstacle moves at most speed * t (a mirror bounce only shortens the displacement).
    const float travel = moving ? field.velocity(env, k).norm() * seconds : 0.0f;
    const float far = (states_ ? std::max(reach_, kStateReach) : reach_) + extent + r + travel;
    const float dx = c.x() - root.x, dz = c.y() - root.z;
    if (dx * dx + dz * dz > far * far) continue;
    if (moving) field.path(env, k, frames, frame_dt, scratch_x_.data(), scratch_z_.data());
    for (int s = 0; s < samples_; ++s) {
      const size_t o = static_cast<size_t>(s) * capacity_ + kept_;
      cx_[o] = moving ? scratch_x_[kPathSampleFrames[s] - 1] : c.x();
      cz_[o] = moving ? scratch_z_[kPathSampleFrames[s] - 1] : c.y();
      // Whether a path point of sample s can reach it there (a row's point lies within the
      // database's path_reach of the root, a state's within kStateReach; a millimetre of slack).
      const float reach = states_ ? std::max(db_->path_reach[s], kStateReach) : db_->path_reach[s];
      const float near = reach + extent + r + 1e-3f;
      const float sx = cx_[o] - root.x, sz = cz_[o] - root.z;
      if (sx * sx + sz * sz <= near * near) near_[static_cast<size_t>(s) * capacity_ + near_count_[s]++] = kept_;
    }
    const Vec2 rot = field.rotation(env, k);
    ocos_[kept_] = rot.x();
    osin_[kept_] = rot.y();
    hx_[kept_] = h.x();
    hz_[kept_] = h.y();
    bound2_[kept_] = (extent + r) * (extent + r);
    ++kept_;
  }
}

void trajectory_path(const float* raw_trajectory, float* path) {
  const float t[4] = {0.0f, static_cast<float>(kTrajectoryOffsets[0]), static_cast<float>(kTrajectoryOffsets[1]),
                      static_cast<float>(kTrajectoryOffsets[2])};
  // Positions at t[0..3]; features.hpp's layout: per horizon, position (x, z), then direction.
  const float px[4] = {0.0f, raw_trajectory[0], raw_trajectory[4], raw_trajectory[8]};
  const float pz[4] = {0.0f, raw_trajectory[1], raw_trajectory[5], raw_trajectory[9]};
  for (int s = 0; s < kPathSamples; ++s) {
    const float f = static_cast<float>(kPathSampleFrames[s]);
    const int a = f <= t[1] ? 0 : 1;  // the three nodes a, a+1, a+2
    float x = 0.0f, z = 0.0f;
    for (int m = a; m < a + 3; ++m) {
      float w = 1.0f;  // Lagrange basis of node m
      for (int o = a; o < a + 3; ++o)
        if (o != m) w *= (f - t[o]) / (t[m] - t[o]);
      x += w * px[m];
      z += w * pz[m];
    }
    path[2 * s] = x;
    path[2 * s + 1] = z;
  }
}

int ObstaclePathFilter::first_hit_state(const float* features) const {
  if (!states_) throw std::invalid_argument("path filter: first_hit_state before set_prices_states(true)");
  float raw[kTrajectoryDim], path[kPathSamples * 2];
  trajectory_denormalize(*db_, features + kPoseDim, raw);
  trajectory_path(raw, path);
  for (int s = 0; s < kPathSamples; ++s) {
    const float d = std::hypot(path[2 * s], path[2 * s + 1]);
    if (d > kStateReach) path[2 * s] *= kStateReach / d, path[2 * s + 1] *= kStateReach / d;
  }
  return first_hit_path(path);
}

int ObstaclePathFilter::first_hit_path(const float* p) const {
  const float r2 = config_.radius * config_.radius;
  for (int s = 0; s < samples_; ++s) {
    // local_to_world_xz (math.hpp) of the path point, through the character's root.
    const float px = p[2 * s], pz = p[2 * s + 1];
    const float wx = root_x_ + cos_yaw_ * px + sin_yaw_ * pz;
    const float wz = root_z_ - sin_yaw_ * px + cos_yaw_ * pz;
    const float* xs = &cx_[static_cast<size_t>(s) * capacity_];
    const float* zs = &cz_[static_cast<size_t>(s) * capacity_];
    const int32_t* near = &near_[static_cast<size_t>(s) * capacity_];
    for (int j = 0; j < near_count_[s]; ++j) {
      const int k = near[j];
      const float dx = wx - xs[k], dz = wz - zs[k];
      if (dx * dx + dz * dz > bound2_[k]) continue;
      const float u = ocos_[k] * dx - osin_[k] * dz, v = osin_[k] * dx + ocos_[k] * dz;
      const float du = std::max(std::abs(u) - hx_[k], 0.0f), dv = std::max(std::abs(v) - hz_[k], 0.0f);
      if (du * du + dv * dv <= r2) return s;
    }
  }
  return -1;
}

}  // namespace mmrl
