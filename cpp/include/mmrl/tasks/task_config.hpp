// The numbers every target-reaching task has (the base of each task's config) and the option
// table: each field is declared once, as a member with its default, and listed once in its
// config's visit() with its range and a one-line doc. From that table come the Python config
// (python/mmrl/tasks/options.py builds the dataclass: names, types, defaults, docs), the
// bindings' properties and their docs (so the stub), the runtime file loader (by field name),
// and the range checks (check_options, one message for every option).
//
// A task's config derives from TaskConfig, adds its own fields, and lists them:
//   struct MyTaskConfig : TaskConfig {
//     float my_radius = 1.0f;
//     template <class Visit> static void visit(Visit&& v) {
//       visit_task_config_fields(v);
//       v("my_radius", &MyTaskConfig::my_radius, kPositive, "Radius of my thing (meters).");
//     }
//   };
// Cross-field rules (target_half_extent > min_target_distance, ...) stay in the task's checks.
#pragma once

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "mmrl/decision.hpp"

namespace mmrl {

// The values a numeric option accepts: [lo, hi], lo excluded when lo_open; finite unless
// inf_ok (which allows +inf). Booleans and lists take kAny (not checked).
struct OptionRange {
  double lo, hi;
  bool lo_open = false;
  bool inf_ok = false;
};
constexpr double kOptionInf = std::numeric_limits<double>::infinity();
constexpr OptionRange kAny{-kOptionInf, kOptionInf};
constexpr OptionRange kNonNegative{0.0, kOptionInf};
constexpr OptionRange kPositive{0.0, kOptionInf, true};
constexpr OptionRange closed_range(double lo, double hi) { return OptionRange{lo, hi}; }

// std::invalid_argument "NAME must be ..., got VALUE" unless `value` is in `range`.
void check_option(const char* name, double value, const OptionRange& range);

// Every numeric field of a config against its range (Config::visit).
template <class Config>
void check_options(const Config& c) {
  Config::visit([&](const char* name, auto member, const OptionRange& range, const char*) {
    using T = typename std::decay<decltype(c.*member)>::type;
    if constexpr (std::is_arithmetic<T>::value && !std::is_same<T, bool>::value)
      check_option(name, static_cast<double>(c.*member), range);
  });
}

// An option of an experiment that lost, removed from the code: its name and the value the code
// now always runs. A saved config or controller file with that value loads as before; any other
// value is refused naming it (the Python configs and the runtime's loader read this one table).
struct RetiredOption {
  const char* name;
  double now;
  bool deployed = true;  // false: a training option (the reward's) that a controller file may hold with any value
};

// A task's config derives from this (a registered rule finds its task's own numbers by
// dynamic_cast: rules.hpp). A config with retired options hides `retired`.
struct TaskConfig {
  static std::vector<RetiredOption> retired() { return {}; }
  TaskConfig() = default;
  TaskConfig(const TaskConfig&) = default;
  TaskConfig(TaskConfig&&) = default;
  TaskConfig& operator=(const TaskConfig&) = default;
  TaskConfig& operator=(TaskConfig&&) = default;
  virtual ~TaskConfig() = default;
  int frames_per_step = 6;
  float target_half_extent = 5.0f;
  float min_target_distance = 0.6f;
  float success_radius = 0.5f;
  float success_bonus = 1000.0f;
  int max_steps = 100;
  float action_limit_std = 3.0f;
  bool random_heading = true;
  float transition_cost = 0.0f;
  float transition_pose_weight = 0.0f;
  float transition_penalty = 0.0f;
  float foot_jump_limit = 0.0f;
  std::vector<float> clip_costs;            // one per clip (Python: a "PATTERN=COST;..." spec)
  std::vector<std::string> request_groups;  // (Python: "style,gait")
  float request_any = 0.125f;
};

// The base's fields, in declaration order.
template <class Visit>
void visit_task_config_fields(Visit&& v) {
  v("frames_per_step", &TaskConfig::frames_per_step, closed_range(1, kMaxFramesPerStep),
    "Frames played per RL step (6 = 0.2 s at 30 fps).");
  v("target_half_extent", &TaskConfig::target_half_extent, kPositive,
    "Targets are uniform in a square of side 2 * this (meters) around the start (a stage's, with a curriculum).");
  v("min_target_distance", &TaskConfig::min_target_distance, kNonNegative,
    "Targets closer than this (meters) to the start are redrawn, so no episode starts solved.");
  v("success_radius", &TaskConfig::success_radius, kPositive,
    "Reaching within this distance (meters) of the target is success.");
  v("success_bonus", &TaskConfig::success_bonus, kAny, "Reward added on success.");
  v("max_steps", &TaskConfig::max_steps, closed_range(1, 1e9),
    "Steps before truncation (100 steps = 20 s at 6 frames per step).");
  v("action_limit_std", &TaskConfig::action_limit_std, kPositive,
    "Half-width of the action box in standard deviations of each normalized trajectory feature.");
  v("random_heading", &TaskConfig::random_heading, kAny,
    "Start with a uniformly random heading (else facing +Z).");
  v("transition_cost", &TaskConfig::transition_cost, kNonNegative,
    "Squared normalized feature distance by which another frame must beat the playing clip's continuation "
    "to replace it; 0 is the paper's rule.");
  v("transition_pose_weight", &TaskConfig::transition_pose_weight, kNonNegative,
    "Reward term: minus this times the squared normalized pose-feature distance a transition asks the blend "
    "to hide; 0 is the paper's reward.");
  v("transition_penalty", &TaskConfig::transition_penalty, kNonNegative,
    "Reward term: minus this at every transition, in the reward's own units; 0 is the paper's reward.");
  v("foot_jump_limit", &TaskConfig::foot_jump_limit, kNonNegative,
    "A match refuses frames whose feet stand farther than this (meters, in the character frame) from the "
    "shown frame's, unless every frame is refused: the blend of a transition never has to slide a foot "
    "further. 0: off.");
  v("clip_costs", &TaskConfig::clip_costs, kAny,
    "Costs added to the match cost of chosen clips: 'PATTERN=COST;...', each PATTERN an fnmatch pattern of "
    "clip names, each COST >= 0 or inf (never play them); costs of patterns matching one clip add up.");
  v("request_groups", &TaskConfig::request_groups, kAny,
    "Tag groups the policy is conditioned on, comma-separated ('style,gait'; docs/styles.md): each episode "
    "draws a request over them and the observation ends with its code.");
  v("request_any", &TaskConfig::request_any, closed_range(0, 1),
    "Per conditioned group, the probability that an episode's request leaves it free.");
}

// The base's cross-field rule (std::invalid_argument naming the fields): target_half_extent
// larger than min_target_distance. The ranges (frames_per_step's included) are check_options'. (clip_costs needs the database: ClipCostFilter checks it.)
void check_task_config(const TaskConfig& c);

}  // namespace mmrl
