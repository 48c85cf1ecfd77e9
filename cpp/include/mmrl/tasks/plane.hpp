// The plane task (paper, section 3) on the batched target-reaching env (vecenv.hpp, which
// owns the pool, the RNGs, the valid frames, the autoreset and the bookkeeping):
//   observation  [c_t (15): normalized pose features of the current frame,
//                 g_t (2): target (x, z) in the character frame, meters,
//                 with request_groups: the request's code (vecenv.hpp's request_dim floats)]
//   action       12-d trajectory feature in the database's normalized units, clipped to a
//                per-dimension box of mean +- action_limit_std * std over valid frames
//   reward       exp(-|g_t|) after the step, + success_bonus on success
//   terminated   the root came within success_radius of the target on any played frame
//                (every frame of the step is played: the step does not stop there; the
//                step's frames played (step_frames) count up to that first frame)
//   truncated    max_steps steps without success
#pragma once

#include <cstdint>

#include "mmrl/vecenv.hpp"

namespace mmrl {

// The plane task adds nothing to the base (tasks/task_config.hpp).
struct PlaneTaskConfig : TaskConfig {
  template <class Visit>
  static void visit(Visit&& v) {
    visit_task_config_fields(v);
  }
};
using TargetTaskConfig = PlaneTaskConfig;  // the old name, deprecated: kept for one release

class PlaneTask : public TargetTask<PlaneTask, PlaneTaskConfig, TargetEnvState> {
 public:
  static constexpr int kObsDim = kPoseDim + 2;
  static constexpr int kActionDim = kTrajectoryDim;
  static constexpr bool kStepEndsAtEvent = false;  // the step plays on past the frame that succeeded
  static constexpr const char* kCoreName = "plane";  // the name a controller file gives this core
  int obs_dim() const { return kObsDim + request_dim(); }  // with request_groups: the request's code last
  ObsLayout task_obs_layout() const { return {{"pose", kPoseDim, ""}, {"goal", 2, ""}}; }

  // db and matcher are borrowed and must outlive the task. Throws std::invalid_argument on a
  // bad config.
  PlaneTask(const Database& db, const Matcher& matcher, int num_envs, const PlaneTaskConfig& config);

  void observe(int i, float* obs_row) const;

 private:
  friend class TargetTask<PlaneTask, PlaneTaskConfig, TargetEnvState>;
  void begin_episode(int i);
  FrameEvent played_frame(int i, const RootState& before) const;
  TaskStep end_step(int i, FrameEvent event) const;
};

// The plane task's batched environments (vecenv.hpp's pool).
class PlaneVecEnv : public TargetVecEnv<PlaneTask> {
 public:
  using TargetVecEnv::TargetVecEnv;
  // actions: N x 12 (finite; checked by the caller). Outputs are N rows each. final_obs rows
  // are written only where an episode ended; episode_return/length likewise.
  void step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
            uint8_t* success, float* final_obs, float* episode_return, int32_t* episode_length);
  // The same with every output in one record (and the optional per-step rows, vecenv.hpp).
  void step(const float* actions, const TargetStepBuffers& out);
};

}  // namespace mmrl
