#include "mmrl/vecenv.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace mmrl {

void check_task_config(const TaskConfig& c) {
  auto finite = [](float v) { return std::isfinite(v); };
  check_frames_per_step(c.frames_per_step);
  if (!(c.success_radius > 0) || !finite(c.success_radius))
    throw std::invalid_argument("success_radius must be finite and > 0, got " + std::to_string(c.success_radius));
  if (c.max_steps < 1) throw std::invalid_argument("max_steps must be >= 1, got " + std::to_string(c.max_steps));
  if (!(c.action_limit_std > 0) || !finite(c.action_limit_std))
    throw std::invalid_argument("action_limit_std must be finite and > 0, got " + std::to_string(c.action_limit_std));
  if (!(c.min_target_distance >= 0) || !(c.target_half_extent > c.min_target_distance) || !finite(c.target_half_extent))
    throw std::invalid_argument("target_half_extent must be finite and larger than min_target_distance >= 0");
  if (!finite(c.success_bonus)) throw std::invalid_argument("success_bonus must be finite");
  if (!(c.transition_cost >= 0.0f) || !finite(c.transition_cost))
    throw std::invalid_argument("transition_cost must be finite and >= 0");
  if (!(c.transition_pose_weight >= 0.0f) || !finite(c.transition_pose_weight))
    throw std::invalid_argument("transition_pose_weight must be finite and >= 0");
  if (!(c.transition_penalty >= 0.0f) || !finite(c.transition_penalty))
    throw std::invalid_argument("transition_penalty must be finite and >= 0");
}

void target_env_check(const Database& db, const Matcher& matcher, int num_envs, const TaskConfig& config) {
  if (num_envs < 1) throw std::invalid_argument("num_envs must be >= 1");
  check_task_config(config);
  if (matcher.num_rows() != db.num_frames) throw std::invalid_argument("matcher was not built over this database");
  if (db.valid_frames.empty())
    throw std::invalid_argument("the database has no valid frames (every clip is shorter than 31 frames)");
}

}  // namespace mmrl
