// The plane task (paper, section 3) on the batched target-reaching env (vecenv.hpp, which
// owns the pool, the RNGs, the valid frames, the autoreset and the bookkeeping):
//   observation  [c_t (15): normalized pose features of the current frame,
//                 g_t (2): target (x, z) in the character frame, meters]
//   action       12-d trajectory feature in the database's normalized units, clipped to a
//                per-dimension box of mean +- action_limit_std * std over valid frames
//   reward       exp(-|g_t|) after the step, + success_bonus on success
//   terminated   the root came within success_radius of the target on any played frame
//                (every frame of the step is played: the step does not stop there; the
//                step's frames played (last_step_frames) count up to that first frame)
//   truncated    max_steps steps without success
#pragma once

#include <cstdint>
#include <vector>

#include "mmrl/vecenv.hpp"

namespace mmrl {

struct TargetTaskConfig {
  int frames_per_step = 6;           // frames played per RL step (0.2 s at 30 fps)
  float target_half_extent = 5.0f;   // targets uniform in a (2h x 2h) m square around the start
  float min_target_distance = 0.6f;  // targets closer than this to the start are redrawn
  float success_radius = 0.5f;       // meters
  float success_bonus = 1000.0f;
  int max_steps = 100;               // truncation (20 s at 6 frames per step, 30 fps)
  float action_limit_std = 3.0f;     // action box half-width, in standard deviations
  bool random_heading = true;        // start heading uniform in [-pi, pi)
  float transition_cost = 0.0f;      // continuation bias of the match (controller.hpp); 0: the paper's rule
  // Per clip, added to the match cost of its frames (+inf: never played); empty: none. The
  // candidate filter of controller.hpp's ClipCostFilter.
  std::vector<float> clip_costs;
  // Reward - transition_pose_weight * (the squared normalized, weighted distance between the pose
  // features of the continuation and of the matched frame: what a transition asks the blend
  // to hide; 0 without a transition). 0: the paper's reward.
  float transition_pose_weight = 0.0f;
};

class PlaneVecEnv : public TargetVecEnv<PlaneVecEnv, TargetTaskConfig, TargetEnvState> {
 public:
  static constexpr int kObsDim = kPoseDim + 2;
  static constexpr int kActionDim = kTrajectoryDim;

  // db and matcher are borrowed and must outlive the env. num_threads 0 = all cores.
  // Throws std::invalid_argument on a bad config.
  PlaneVecEnv(const Database& db, const Matcher& matcher, int num_envs, const TargetTaskConfig& config,
              int num_threads = 0);

  // actions: N x 12 (finite; checked by the caller). Outputs are N rows each. final_obs rows
  // are written only where an episode ended; episode_return/length likewise.
  void step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
            uint8_t* success, float* final_obs, float* episode_return, int32_t* episode_length);

  void observe(int i, float* obs_row) const;

 private:
  friend class TargetVecEnv<PlaneVecEnv, TargetTaskConfig, TargetEnvState>;
  void begin_episode(int i);
  TaskStep advance(int i, const float* action);
};

}  // namespace mmrl
