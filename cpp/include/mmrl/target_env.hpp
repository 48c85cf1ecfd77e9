// What every target task's environment keeps and reports, apart from the loop that steps it
// (vecenv.hpp's TargetTask and TargetVecEnv): the per-environment state, one step's outcome and output
// buffers, the per-env decision statistics, and the episode-start rules (a start frame, a root
// and a target) with the checks every task makes.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "mmrl/decider.hpp"
#include "mmrl/rng.hpp"
#include "mmrl/tags.hpp"
#include "mmrl/tasks/task_config.hpp"

namespace mmrl {

// The decisions of one env since they were last popped (training's cheap quality log):
// decisions (steps that matched), transitions among them, their matched costs summed, frames
// played.
struct MatchStats {
  int64_t decisions = 0, transitions = 0, frames = 0;
  double cost_sum = 0;
};

// Per-environment state every target task keeps (world meters, radians). Its motion (the
// database frame shown, or a compressed state) is the MotionState it derives from.
struct TargetEnvState : MotionState {
  RootState root;
  float target_x = 0, target_z = 0;
  int steps = 0;
  double episode_return = 0;
  Decision decision;  // the last decision (cleared by a reset)
  // The last step's decision, kept through the autoreset (so it describes the step just
  // returned); cleared by reset(seed) and by a NEXT_STEP reset step.
  Decision last_step;
  // Frames the last step played before its episode ended: the index of the frame of the
  // ending event + 1, or frames_per_step when the step did not end the episode (truncation
  // included). Kept like last_step; 0 after reset(seed).
  int step_frames = 0;
  // NEXT_STEP autoreset: the episode ended on the last step and the next step resets it.
  bool autoreset_pending = false;
  int64_t episode_frames = 0;  // frames played in this episode (the last step up to its ending frame)
  MatchStats stats;            // since the last pop_match_stats
  Rng rng;
  // The request (tags.hpp) env i's matches and episode starts keep to: pinned by set_request,
  // else drawn per episode from the env's RequestMix (request_index; -1: every clip).
  bool request_pinned = false;
  int request_index = -1;
  RequestSelection pinned_request;
  std::vector<float> pinned_code;
};

// A task's observation, segment by segment in order (name, floats): what a policy, a network
// or a scripted joystick reads where ("pose", "goal", "maps", "request", ...), never guessed
// from the observation's length.
struct ObsSegment {
  std::string name;
  int size = 0;
  std::string option;  // the setting that adds this segment ("" when every controller has it)
};
using ObsLayout = std::vector<ObsSegment>;

// What a played frame did to an episode: nothing, reached the task's goal, or failed it (a
// collision). A step's first event ends its episode.
enum class FrameEvent : uint8_t { kNone, kSuccess, kFailure };

// One task step's outcome (before truncation, which the pool decides: vecenv.hpp).
struct TaskStep {
  float reward = 0;
  bool terminated = false;
  bool success = false;
  int step_frames = 0;  // see TargetEnvState::step_frames
};

// The step outputs every task writes, N rows each (obs and final_obs: N x obs_dim()).
// final_obs, episode_return and episode_length rows are written only where an episode ended.
// The last three are optional (null: not written): each env's step_frames and its
// decision (a transition, the matched cost), every row on every step, so one call returns
// everything a step produced.
struct TargetStepBuffers {
  float* obs;
  float* rewards;
  uint8_t* terminated;
  uint8_t* truncated;
  uint8_t* success;
  float* final_obs;
  float* episode_return;
  int32_t* episode_length;
  int32_t* step_frames = nullptr;
  uint8_t* transitions = nullptr;
  float* costs = nullptr;
  int64_t* episode_frames = nullptr;  // optional, written only where an episode ended
};

// Draws an episode start shared by the target tasks: a uniformly random valid frame, the
// root at the origin with a random (or zero) heading, and a target uniform in the square
// [-half_extent, half_extent]^2, redrawn while closer than min_target_distance.
// A target offset (meters) uniform in [-half_extent, half_extent]^2, redrawn while closer than
// min_target_distance: the episode start's rule, also for a new target where a character stands.
inline void draw_target_offset(Rng& rng, float half_extent, float min_target_distance, float* dx, float* dz) {
  do {
    *dx = rng.uniform(-half_extent, half_extent);
    *dz = rng.uniform(-half_extent, half_extent);
  } while (std::hypot(*dx, *dz) < min_target_distance);
}

// starts: the frames to start from (tags.hpp: the valid frames of a request's clips, or of all).
inline void draw_episode_start(Rng& rng, const RequestSelection& starts, bool random_heading,
                               float half_extent, float min_target_distance, int64_t* frame, RootState* root,
                               float* target_x, float* target_z) {
  *frame = starts.start_frame(static_cast<int64_t>(rng.below(static_cast<uint64_t>(starts.num_start_frames()))));
  *root = RootState{};
  root->yaw = random_heading ? rng.uniform(-kPi, kPi) : 0.0f;
  draw_target_offset(rng, half_extent, min_target_distance, target_x, target_z);
}

// The checks every target task makes (std::invalid_argument): num_envs >= 1, the config's
// base numbers (check_task_config), the matcher built over db, and at least one valid frame
// (the episode starts: db.valid_frames).
void target_env_check(const Database& db, const Matcher& matcher, int num_envs, const TaskConfig& config);

}  // namespace mmrl
