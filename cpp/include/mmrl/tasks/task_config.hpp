// The numbers every target-reaching task has (the base of each task's config), the one place
// they are checked, and a field table that the bindings, the runtime file loader and the
// defaults test read, so a field is declared once.
//
// A task's config derives from TaskConfig, adds its own fields, and lists them:
//   struct MyTaskConfig : TaskConfig {
//     float my_radius = 1.0f;
//     template <class Visit> static void visit(Visit&& v) {
//       visit_task_config_fields(v);
//       v("my_radius", &MyTaskConfig::my_radius);
//     }
//   };
// Each v(name, member pointer) call names a field as Python's config dataclass names it.
#pragma once

#include <string>
#include <vector>

#include "mmrl/decision.hpp"

namespace mmrl {

struct TaskConfig {
  int frames_per_step = 6;           // frames played per RL step (0.2 s at 30 fps), 1..kMaxFramesPerStep
  float target_half_extent = 5.0f;   // targets uniform in a (2h x 2h) m square around the start
  float min_target_distance = 0.6f;  // targets closer than this to the start are redrawn
  float success_radius = 0.5f;       // meters
  float success_bonus = 1000.0f;     // reward on success
  int max_steps = 100;               // truncation (20 s at 6 frames per step, 30 fps)
  float action_limit_std = 3.0f;     // action box half-width, in standard deviations
  bool random_heading = true;        // start heading uniform in [-pi, pi)
  float transition_cost = 0.0f;      // transition cost of the match (decision.hpp); 0: the paper's rule
  // Reward - transition_pose_weight * (the squared normalized, weighted distance between the pose
  // features of the continuation and of the matched frame: what a transition asks the blend
  // to hide; 0 without a transition). 0: the paper's reward.
  float transition_pose_weight = 0.0f;
  // Reward - transition_penalty at each decision whose match is a transition (not the
  // continuation), in the reward's own units (the plane task's reward per step is at most 1
  // before the success bonus), so it means the same on every database. 0: the paper's reward.
  float transition_penalty = 0.0f;
  // Per clip, added to the match cost of its frames (+inf: never played); empty: none. The
  // candidate filter of decision.hpp's ClipCostFilter.
  std::vector<float> clip_costs;
  // Tag groups the policy is conditioned on (tags.hpp's RequestCode): the observation ends
  // with the request's code, and each episode draws a request over these groups (RequestMix).
  // Empty: no request code, and every episode plays every clip unless a request is set.
  std::vector<std::string> request_groups;
  // Per group, the probability that an episode's request leaves it free (any value).
  float request_any = 0.125f;
};

// The base's fields, in declaration order.
template <class Visit>
void visit_task_config_fields(Visit&& v) {
  v("frames_per_step", &TaskConfig::frames_per_step);
  v("target_half_extent", &TaskConfig::target_half_extent);
  v("min_target_distance", &TaskConfig::min_target_distance);
  v("success_radius", &TaskConfig::success_radius);
  v("success_bonus", &TaskConfig::success_bonus);
  v("max_steps", &TaskConfig::max_steps);
  v("action_limit_std", &TaskConfig::action_limit_std);
  v("random_heading", &TaskConfig::random_heading);
  v("transition_cost", &TaskConfig::transition_cost);
  v("transition_pose_weight", &TaskConfig::transition_pose_weight);
  v("transition_penalty", &TaskConfig::transition_penalty);
  v("clip_costs", &TaskConfig::clip_costs);
  v("request_groups", &TaskConfig::request_groups);
  v("request_any", &TaskConfig::request_any);
}

// Checks the base's numbers (std::invalid_argument naming the field): frames_per_step in
// [1, kMaxFramesPerStep], success_radius, max_steps and action_limit_std positive,
// target_half_extent finite and larger than min_target_distance >= 0, success_bonus finite,
// transition_cost, transition_pose_weight and transition_penalty finite and >= 0. (clip_costs needs the database:
// ClipCostFilter checks it.)
void check_task_config(const TaskConfig& c);

}  // namespace mmrl
