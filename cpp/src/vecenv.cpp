#include "mmrl/vecenv.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace mmrl {

PlaneVecEnv::PlaneVecEnv(const Database& db, const Matcher& matcher, int num_envs, const TargetTaskConfig& config,
                         int num_threads)
    : db_(db), matcher_(matcher), config_(config), envs_(static_cast<size_t>(std::max(0, num_envs))), pool_(num_threads) {
  if (num_envs < 1) throw std::invalid_argument("num_envs must be >= 1");
  if (config.frames_per_step < 1 || config.frames_per_step > kTrajectoryOffsets[2])
    throw std::invalid_argument("frames_per_step must be between 1 and 30");
  if (!(config.target_half_extent > 0) || !(config.success_radius > 0) || config.max_steps < 1 ||
      !(config.action_limit_std > 0))
    throw std::invalid_argument("target_half_extent, success_radius, max_steps and action_limit_std must be positive");
  if (config.min_target_distance >= config.target_half_extent)
    throw std::invalid_argument("min_target_distance must be smaller than target_half_extent");
  if (matcher.num_rows() != db.num_frames) throw std::invalid_argument("matcher was not built over this database");
  for (int64_t i = 0; i < db.num_frames; ++i)
    if (db.valid[i]) valid_frames_.push_back(i);
  if (valid_frames_.empty()) throw std::invalid_argument("the database has no valid frames (every clip is shorter than 31 frames)");
  trajectory_action_box(db, config.action_limit_std, low_, high_);
  for (int i = 0; i < num_envs; ++i) envs_[i].rng = Rng(0, static_cast<uint64_t>(i));
}

void PlaneVecEnv::observe(int i, float* obs) const {
  const TargetEnvState& s = envs_[i];
  const float* pose = &db_.normalized[static_cast<size_t>(s.frame) * kFeatureDim];
  for (int k = 0; k < kPoseDim; ++k) obs[k] = pose[k];
  const Vec2 g = world_to_local_xz(s.target_x - s.root.x, s.target_z - s.root.z, s.root.yaw);
  obs[kPoseDim] = g.x();
  obs[kPoseDim + 1] = g.y();
}

void PlaneVecEnv::set_target(int i, float x, float z) {
  envs_[i].target_x = x;
  envs_[i].target_z = z;
}

void PlaneVecEnv::reset_env(int i, float* obs_row) {
  TargetEnvState& s = envs_[i];
  draw_episode_start(s.rng, valid_frames_, config_.random_heading, config_.target_half_extent,
                     config_.min_target_distance, &s.frame, &s.root, &s.target_x, &s.target_z);
  s.steps = 0;
  s.episode_return = 0;
  s.last_match = -1;
  s.last_transition = false;
  if (obs_row) observe(i, obs_row);
}

void PlaneVecEnv::reset(uint64_t seed, float* obs) {
  for (int i = 0; i < num_envs(); ++i) {
    envs_[i].rng = Rng(seed, static_cast<uint64_t>(i));
    reset_env(i, obs ? obs + static_cast<size_t>(i) * kObsDim : nullptr);
  }
}

bool PlaneVecEnv::advance(int i, const float* action, float* reward, bool* terminated, bool* truncated) {
  TargetEnvState& s = envs_[i];
  const int64_t j = controller_decide(db_, matcher_, s.frame, action, low_, high_);
  s.last_transition = (j != s.frame);
  s.last_match = j;
  const float r2 = config_.success_radius * config_.success_radius;
  bool success = false;
  for (int k = 0; k < config_.frames_per_step; ++k) {
    root_advance(s.root, &db_.root_deltas[static_cast<size_t>(j + k) * 3]);
    const float dx = s.target_x - s.root.x, dz = s.target_z - s.root.z;
    if (dx * dx + dz * dz <= r2) success = true;  // tested on every played frame
  }
  s.frame = j + config_.frames_per_step;
  s.steps += 1;
  const float dist = std::hypot(s.target_x - s.root.x, s.target_z - s.root.z);
  *reward = std::exp(-dist) + (success ? config_.success_bonus : 0.0f);
  *terminated = success;
  *truncated = !success && s.steps >= config_.max_steps;
  s.episode_return += *reward;
  return success;
}

void PlaneVecEnv::step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
                       uint8_t* success, float* final_obs, float* episode_return, int32_t* episode_length) {
  pool_.parallel_for(num_envs(), [&](int64_t b, int64_t e, int) {
    for (int64_t i = b; i < e; ++i) {
      bool term = false, trunc = false;
      const bool ok = advance(static_cast<int>(i), actions + i * kActionDim, &rewards[i], &term, &trunc);
      terminated[i] = term;
      truncated[i] = trunc;
      success[i] = ok;
      float* row = obs + i * kObsDim;
      if (term || trunc) {
        observe(static_cast<int>(i), final_obs + i * kObsDim);
        episode_return[i] = static_cast<float>(envs_[i].episode_return);
        episode_length[i] = envs_[i].steps;
        reset_env(static_cast<int>(i), row);
      } else {
        observe(static_cast<int>(i), row);
      }
    }
  }, 4);
}

}  // namespace mmrl
