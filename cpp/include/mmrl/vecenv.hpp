// Batched environment cores: N characters step in one call over a thread pool, writing
// observations, rewards and flags into caller-owned buffers (numpy arrays in Python).
// Nothing is allocated per step.
//
// Plane task (paper, section 3):
//   observation  [c_t (15): normalized pose features of the current frame,
//                 g_t (2): target (x, z) in the character frame, meters]
//   action       12-d trajectory feature in the database's normalized units, clipped to a
//                per-dimension box of mean +- action_limit_std * std over valid frames
//   reward       exp(-|g_t|) after the step, + success_bonus on success
//   terminated   the root came within success_radius of the target on any played frame
//   truncated    max_steps steps without success
// Autoreset is SAME_STEP: a finished environment's last observation goes to final_obs and
// the environment is reset at once, its first observation written to obs.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "mmrl/controller.hpp"
#include "mmrl/rng.hpp"
#include "mmrl/threadpool.hpp"

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
};

struct TargetEnvState {
  RootState root;
  int64_t frame = 0;        // current database frame
  float target_x = 0, target_z = 0;
  int steps = 0;
  double episode_return = 0;
  int64_t last_match = -1;  // frame chosen by the last match
  bool last_transition = false;
  Rng rng;
};

// Draws an episode start shared by the target tasks: a uniformly random valid frame, the
// root at the origin with a random (or zero) heading, and a target uniform in the square
// [-half_extent, half_extent]^2, redrawn while closer than min_target_distance.
inline void draw_episode_start(Rng& rng, const std::vector<int64_t>& valid_frames, bool random_heading,
                               float half_extent, float min_target_distance, int64_t* frame, RootState* root,
                               float* target_x, float* target_z) {
  *frame = valid_frames[rng.below(valid_frames.size())];
  *root = RootState{};
  root->yaw = random_heading ? rng.uniform(-kPi, kPi) : 0.0f;
  do {
    *target_x = rng.uniform(-half_extent, half_extent);
    *target_z = rng.uniform(-half_extent, half_extent);
  } while (std::hypot(*target_x, *target_z) < min_target_distance);
}

class PlaneVecEnv {
 public:
  static constexpr int kObsDim = kPoseDim + 2;
  static constexpr int kActionDim = kTrajectoryDim;

  // db and matcher are borrowed and must outlive the env. num_threads 0 = all cores.
  PlaneVecEnv(const Database& db, const Matcher& matcher, int num_envs, const TargetTaskConfig& config,
              int num_threads = 0);

  int num_envs() const { return static_cast<int>(envs_.size()); }
  const TargetTaskConfig& config() const { return config_; }
  const float* action_low() const { return low_; }
  const float* action_high() const { return high_; }

  // Reseeds every environment's RNG from (seed, index) and resets all; obs: N x kObsDim.
  void reset(uint64_t seed, float* obs);
  // Resets environment i from its own RNG stream; writes its observation row.
  void reset_env(int i, float* obs_row);

  // actions: N x 12 (finite; checked by the caller). Outputs are N rows each. final_obs rows
  // are written only where an episode ended; episode_return/length likewise.
  void step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
            uint8_t* success, float* final_obs, float* episode_return, int32_t* episode_length);

  TargetEnvState& state(int i) { return envs_[i]; }
  const TargetEnvState& state(int i) const { return envs_[i]; }
  void observe(int i, float* obs_row) const;
  // Moves env i's target (world meters), e.g. for evaluation sequences.
  void set_target(int i, float x, float z);

 private:
  // One RL step of env i without autoreset; returns true on success.
  bool advance(int i, const float* action, float* reward, bool* terminated, bool* truncated);

  const Database& db_;
  const Matcher& matcher_;
  TargetTaskConfig config_;
  std::vector<TargetEnvState> envs_;
  std::vector<int64_t> valid_frames_;
  float low_[kTrajectoryDim], high_[kTrajectoryDim];
  ThreadPool pool_;
};

}  // namespace mmrl
