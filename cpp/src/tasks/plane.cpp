#include "mmrl/tasks/plane.hpp"

#include <cmath>
#include <stdexcept>

namespace mmrl {


PlaneVecEnv::PlaneVecEnv(const Database& db, const Matcher& matcher, int num_envs, const PlaneTaskConfig& config,
                         int num_threads)
    : TargetVecEnv(db, matcher, num_envs, config, num_threads) {}

void PlaneVecEnv::observe(int i, float* obs) const {
  const TargetEnvState& s = envs_[i];
  observe_pose(s, obs);
  observe_goal(s, obs + kPoseDim);
  observe_request(i, obs + kObsDim);
}

void PlaneVecEnv::begin_episode(int i) { draw_start(i, config_.target_half_extent); }

TaskStep PlaneVecEnv::advance(int i, const float* action) {
  TargetEnvState& s = envs_[i];
  decide(i, action);
  const float r2 = config_.success_radius * config_.success_radius;
  TaskStep out;
  out.step_frames = config_.frames_per_step;
  for (int k = 0; k < config_.frames_per_step; ++k) {
    root_advance(s.root, played_delta(s, k));
    const float dx = s.target_x - s.root.x, dz = s.target_z - s.root.z;
    if (dx * dx + dz * dz <= r2 && !out.success) {  // tested on every played frame
      out.success = true;
      out.step_frames = k + 1;
    }
  }
  end_playback(s);
  out.reward = std::exp(-target_distance(s)) + (out.success ? config_.success_bonus : 0.0f);
  out.terminated = out.success;
  return out;
}

void PlaneVecEnv::step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
                       uint8_t* success, float* final_obs, float* episode_return, int32_t* episode_length) {
  step(actions, TargetStepBuffers{obs, rewards, terminated, truncated, success, final_obs, episode_return,
                                  episode_length});
}

void PlaneVecEnv::step(const float* actions, const TargetStepBuffers& out) { step_envs(actions, out, 4, [](int) {}); }

}  // namespace mmrl
