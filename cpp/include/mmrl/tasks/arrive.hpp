// The arrive task (issue 38, docs/arrive.md): reach a target position *and* a facing, and come
// to rest there. A plug-in of the batched target env (vecenv.hpp) like the plane task:
//   observation  [c_t (15): normalized pose features of the current frame,
//                 g_t (2): target (x, z) in the character frame, meters,
//                 f_t (2): the target facing in the character frame, a unit (x, z) vector
//                          (forward = (sin yaw, cos yaw), math.hpp),
//                 with request_groups: the request's code]
//   action       12-d trajectory feature, as the plane task's
//   reward       exp(-|g_t|) + facing_weight * exp(-|g_t| / success_radius) * (1 + cos(facing error)) / 2
//                after the step, + success_bonus * (1 + precision_weight * precision) on success
//                (precision: 1 at the target and its facing, 0 at the tolerances)
//   terminated   success: on hold_time seconds of consecutive played frames the root stood
//                within success_radius of the target, faced its facing within
//                facing_tolerance and its smoothed speed (kRestSmoothingSeconds) stayed below
//                stop_speed (step_frames counts up to the frame that completed the hold)
//   truncated    max_steps steps without success
// Angles are radians everywhere (the facing, its tolerance); a facing is a world yaw about +Y.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

#include "mmrl/vecenv.hpp"

namespace mmrl {

struct ArriveTaskConfig : TaskConfig {
  float facing_tolerance = 0.2618f;  // 15 degrees
  float stop_speed = 0.15f;
  float hold_time = 0.5f;
  float facing_weight = 1.0f;
  float precision_weight = 1.0f;
  float stand_radius = 0.15f;
  float stand_exit = 2.0f;
  float stand_idle_seconds = 3.0f;
  float stand_idle_cost = 120.0f;
  bool stand_anchor = true;
  ArriveTaskConfig() {
    success_radius = 0.15f;
    max_steps = 150;
  }
  template <class Visit>
  static void visit(Visit&& v) {
    visit_task_config_fields(v);
    v("facing_tolerance", &ArriveTaskConfig::facing_tolerance, closed_range(0, 3.1416),
      "Success: the root's yaw within this (radians; 0.2618 = 15 degrees) of the target facing.");
    v("stop_speed", &ArriveTaskConfig::stop_speed, kPositive,
      "Success: the root's speed, smoothed over a quarter second, stays below this (m/s) on every frame of the "
      "hold.");
    v("hold_time", &ArriveTaskConfig::hold_time, closed_range(0, 10),
      "Success: seconds the character stays within the tolerances, at rest, before the episode succeeds.");
    v("facing_weight", &ArriveTaskConfig::facing_weight, kNonNegative,
      "Reward term: this times exp(-distance / success_radius) times (1 + cos(facing error)) / 2.");
    v("precision_weight", &ArriveTaskConfig::precision_weight, kNonNegative,
      "Reward on success: success_bonus times this times the precision of the rest (1 at the target and its "
      "facing, 0 at the tolerances: the mean of 1 - distance / success_radius and 1 - facing error / "
      "facing_tolerance).");
    v("stand_radius", &ArriveTaskConfig::stand_radius, kNonNegative,
      "Within this distance (m) of the target and facing_tolerance of its facing, the match asks to stand at "
      "the target facing its facing (every trajectory sample there) instead of the policy's trajectory: an "
      "arrived character stands. 0: never.");
    v("stand_exit", &ArriveTaskConfig::stand_exit, closed_range(1, 10),
      "Once arrived (a decision at rest within success_radius and facing_tolerance: the hips slower than "
      "stop_speed), the stand holds until the root is farther than stand_exit times success_radius from the "
      "target or turned more than stand_exit times facing_tolerance from its facing. 1: no more than before "
      "arriving.");
    v("stand_idle_seconds", &ArriveTaskConfig::stand_idle_seconds, kNonNegative,
      "Once arrived, the stand's match prefers frames that go on standing this long (s), so that a character "
      "stands through long idles rather than from one short one to the next: a frame that stands for less costs "
      "stand_idle_cost times the share of this time it falls short by (a frame that does not stand: all of it). "
      "Within 5 degrees of its facing a frame stands when it moves less than 0.15 m and turns less than 20 "
      "degrees over the next second, until a foot lifts (a foot is planted below 0.3 m/s); farther, a frame "
      "that turns in place stands too, so the character turns to its facing first. 0: off.");
    v("stand_idle_cost", &ArriveTaskConfig::stand_idle_cost, kNonNegative,
      "The most a stand's match adds for a frame that stands shorter than stand_idle_seconds (squared "
      "normalized feature distance, as transition_cost). 0: off.");
    v("stand_anchor", &ArriveTaskConfig::stand_anchor, kAny,
      "Once arrived, a transition between two poses with both feet planted keeps the feet where they stand: "
      "the root moves so that their mean stays put, and the blend brings the body over them (unless that "
      "takes the root farther from the target than it is and than half success_radius).");
  }
};

struct ArriveEnvState : TargetEnvState {
  float target_yaw = 0;  // the facing to arrive with (world yaw, radians)
  int hold = 0;          // consecutive played frames within the tolerances, at rest
  float vx = 0, vz = 0;   // the root's world velocity (m/s), exponentially smoothed over kRestSmoothingSeconds
  bool arrived = false;  // a decision found it at rest within the tolerances; the stand holds (stand_exit)
};

// The time constant (s) of the smoothed root velocity a rest is read from: a mocap root jitters
// (44% of LAFAN1's idle frames move faster than 0.15 m/s from one frame to the next).
constexpr float kRestSmoothingSeconds = 0.25f;

class ArriveTask : public TargetTask<ArriveTask, ArriveTaskConfig, ArriveEnvState> {
 public:
  static constexpr int kObsDim = kPoseDim + 4;
  static constexpr int kActionDim = kTrajectoryDim;
  static constexpr bool kStepEndsAtEvent = true;  // the step stops where the hold completed
  static constexpr const char* kCoreName = "arrive";  // the name a controller file gives this core
  int obs_dim() const { return kObsDim + request_dim(); }
  ObsLayout task_obs_layout() const { return {{"pose", kPoseDim, ""}, {"goal", 2, ""}, {"facing", 2, ""}}; }

  // db and matcher are borrowed and must outlive the task. Throws std::invalid_argument on a
  // bad config.
  ArriveTask(const Database& db, const Matcher& matcher, int num_envs, const ArriveTaskConfig& config);

  void observe(int i, float* obs_row) const;
  // Sets env i's target facing (world yaw, radians; finite, else std::invalid_argument). A new
  // facing starts a new arrival (the hold and the arrival's stand); the same one changes nothing.
  void set_facing(int i, float yaw);
  // The frames a hold lasts: hold_time in frames (at least 1).
  int hold_frames() const { return hold_frames_; }

 private:
  friend class TargetTask<ArriveTask, ArriveTaskConfig, ArriveEnvState>;
  void begin_episode(int i);
  FrameEvent played_frame(int i, const RootState& before);
  TaskStep end_step(int i, FrameEvent event) const;
  void on_state_set(int i) { envs_[i].hold = 0; }
  // Once arrived (read after decision_action), the character stands: the stand-idle rule prices
  // the match.
  bool standing(int i) const { return config_.stand_radius > 0 && envs_[i].arrived; }
  bool anchors(int i) const { return config_.stand_anchor && standing(i); }
  // Cancels an anchor that would take the root farther from the target than it is and than
  // half the success radius.
  void keep_anchor(int i, float* anchor) const;
  float stand_turn(int i) const { return wrap_angle(envs_[i].target_yaw - envs_[i].root.yaw); }
  // Within stand_radius and facing_tolerance, or once arrived within stand_exit times the
  // tolerances: stand at the target facing its facing, normalized. Updates s.arrived.
  const float* decision_action(int i, const float* action, float* scratch);
  // Within radius of the target and tolerance of its facing.
  bool within(const ArriveEnvState& s, float radius, float tolerance) const;
  bool within(const ArriveEnvState& s, float radius) const { return within(s, radius, config_.facing_tolerance); }
  int hold_frames_ = 1;
  float rest_smoothing_ = 1;  // each played frame's weight in the smoothed velocity
  // The trajectory columns' normalization (mean, divisor), for the stand decision_action writes.
  std::array<float, kTrajectoryDim> stand_mean_{}, stand_scale_{};
  // The hips velocity columns' (x, z) normalization, for the rest test of an arrival.
  float hips_mean_[2] = {}, hips_scale_[2] = {1, 1};
};

// The arrive task's batched environments (vecenv.hpp's pool).
class ArriveVecEnv : public TargetVecEnv<ArriveTask> {
 public:
  using TargetVecEnv::TargetVecEnv;
  void step(const float* actions, const TargetStepBuffers& out);
};

// The arrive task's candidate rule "stand-idle" (rules.cpp registers it): while the character
// stands (RuleContext::standing), a database frame costs stand_idle_cost * max(0, 1 - t /
// stand_idle_seconds), t the seconds it goes on standing still (feature_row_idle and
// idle_row_stands_still: kIdleMeters and kStillDegrees over the next second, for each frame of
// its run of such frames in its clip, up to the last one's second; within 5 degrees of the
// facing no longer than both feet stay planted, foot_planted); a compressed controller's
// candidate (no row) costs nothing. Null unless the config is an arrive task's with both numbers
// above 0.
std::unique_ptr<CandidateRule> make_stand_idle_rule(const RuleSetup& setup);


}  // namespace mmrl
