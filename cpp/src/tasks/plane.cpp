#include "mmrl/tasks/plane.hpp"

#include <cmath>
#include <stdexcept>

namespace mmrl {


PlaneTask::PlaneTask(const Database& db, const Matcher& matcher, int num_envs, const PlaneTaskConfig& config)
    : TargetTask(db, matcher, num_envs, config) {}

void PlaneTask::observe(int i, float* obs) const {
  const TargetEnvState& s = envs_[i];
  observe_pose(s, obs);
  observe_goal(s, obs + kPoseDim);
  observe_request(i, obs + kObsDim);
}

void PlaneTask::begin_episode(int i) { draw_start(i, config_.target_half_extent); }

FrameEvent PlaneTask::played_frame(int i, const RootState&) const {
  return within_success_radius(envs_[i]) ? FrameEvent::kSuccess : FrameEvent::kNone;
}

TaskStep PlaneTask::end_step(int i, FrameEvent event) const {
  TaskStep out;
  out.success = out.terminated = event == FrameEvent::kSuccess;
  out.reward = std::exp(-target_distance(envs_[i])) + (out.success ? config_.success_bonus : 0.0f);
  return out;
}

void PlaneVecEnv::step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
                       uint8_t* success, float* final_obs, float* episode_return, int32_t* episode_length) {
  step(actions, TargetStepBuffers{obs, rewards, terminated, truncated, success, final_obs, episode_return,
                                  episode_length});
}

void PlaneVecEnv::step(const float* actions, const TargetStepBuffers& out) { step_envs(actions, out, 4, [](int) {}); }

}  // namespace mmrl
