#include "mmrl/tasks/arrive.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <utility>
#include <stdexcept>
#include <vector>

#include "mmrl/rules.hpp"

namespace mmrl {

ArriveTask::ArriveTask(const Database& db, const Matcher& matcher, int num_envs, const ArriveTaskConfig& config)
    : TargetTask(db, matcher, num_envs, config),
      hold_frames_(std::max(1, static_cast<int>(std::lround(config.hold_time * db.fps)))),
      rest_smoothing_(1.0f - std::exp(-1.0f / (kRestSmoothingSeconds * db.fps))) {
  const std::array<float, kFeatureDim> scale = db.normalization.column_scale();
  for (int j = 0; j < kTrajectoryDim; ++j) {
    stand_mean_[j] = db.normalization.mean[kPoseDim + j];
    stand_scale_[j] = scale[kPoseDim + j];
  }
  for (int j = 0; j < 2; ++j) {  // features.hpp: [12:15] hips velocity (x, y, z)
    hips_mean_[j] = db.normalization.mean[12 + 2 * j];
    hips_scale_[j] = scale[12 + 2 * j];
  }
}

void ArriveTask::observe(int i, float* obs) const {
  const ArriveEnvState& s = envs_[i];
  observe_pose(s, obs);
  observe_goal(s, obs + kPoseDim);
  const float d = s.target_yaw - s.root.yaw;  // the facing in the character frame: (sin, cos) of its yaw there
  obs[kPoseDim + 2] = std::sin(d);
  obs[kPoseDim + 3] = std::cos(d);
  observe_request(i, obs + kObsDim);
}

void ArriveTask::set_facing(int i, float yaw) {
  if (!std::isfinite(yaw)) throw std::invalid_argument("facing must be finite (radians)");
  ArriveEnvState& s = envs_[i];
  if (wrap_angle(yaw) == s.target_yaw) return;  // the runtime sets it before every decision
  s.target_yaw = wrap_angle(yaw);
  s.hold = 0;
  s.arrived = false;
}

bool ArriveTask::within(const ArriveEnvState& s, float radius, float tolerance) const {
  const float dx = s.target_x - s.root.x, dz = s.target_z - s.root.z;
  return dx * dx + dz * dz <= radius * radius && std::abs(wrap_angle(s.target_yaw - s.root.yaw)) <= tolerance;
}

void ArriveTask::keep_anchor(int i, float* anchor) const {
  if (anchor[0] == 0.0f && anchor[1] == 0.0f) return;
  const ArriveEnvState& s = envs_[i];
  RootState moved = s.root;
  root_shift(moved, anchor);
  const float bx = s.target_x - s.root.x, bz = s.target_z - s.root.z;
  const float ax = s.target_x - moved.x, az = s.target_z - moved.z;
  const float half = 0.5f * config_.success_radius;
  if (ax * ax + az * az > std::max(bx * bx + bz * bz, half * half)) anchor[0] = anchor[1] = 0.0f;
}

const float* ArriveTask::decision_action(int i, const float* action, float* scratch) {
  ArriveEnvState& s = envs_[i];
  if (config_.stand_radius <= 0) return action;
  if (s.arrived) {
    const float widen = config_.stand_exit;
    s.arrived = within(s, widen * config_.success_radius, std::min(widen * config_.facing_tolerance, kPi));
  } else if (within(s, config_.success_radius)) {
    // At rest: the hips of what is shown now (the decision's own motion, so the env, the full
    // path and the runtime, which moves its character's root between decisions, agree).
    const float* pose = source_->current(s).features;
    const float vx = pose[12] * hips_scale_[0] + hips_mean_[0], vz = pose[14] * hips_scale_[1] + hips_mean_[1];
    s.arrived = vx * vx + vz * vz < config_.stop_speed * config_.stop_speed;
  }
  if (!s.arrived && !within(s, config_.stand_radius)) return action;
  // Every sample at the target, facing the target facing, in the character frame: (sin d, cos d).
  const float d = s.target_yaw - s.root.yaw;
  float goal[2];
  observe_goal(s, goal);
  const float raw[4] = {goal[0], goal[1], std::sin(d), std::cos(d)};
  for (int j = 0; j < kTrajectoryDim; ++j) scratch[j] = (raw[j % 4] - stand_mean_[j]) / stand_scale_[j];
  return scratch;
}

void ArriveTask::begin_episode(int i) {
  ArriveEnvState& s = envs_[i];
  draw_start(i, config_.target_half_extent);
  s.target_yaw = s.rng.uniform(-kPi, kPi);
  s.hold = 0;
  s.vx = s.vz = 0;
  s.arrived = false;
}

FrameEvent ArriveTask::played_frame(int i, const RootState& before) {
  ArriveEnvState& s = envs_[i];
  const float fps = db_.fps;
  s.vx += rest_smoothing_ * ((s.root.x - before.x) * fps - s.vx);
  s.vz += rest_smoothing_ * ((s.root.z - before.z) * fps - s.vz);
  const bool resting = std::hypot(s.vx, s.vz) < config_.stop_speed;
  s.hold = resting && within(s, config_.success_radius) ? s.hold + 1 : 0;
  return s.hold >= hold_frames_ ? FrameEvent::kSuccess : FrameEvent::kNone;
}

TaskStep ArriveTask::end_step(int i, FrameEvent event) const {
  const ArriveEnvState& s = envs_[i];  // the root stands where the hold completed (the episode ends there)
  TaskStep out;
  out.success = out.terminated = event == FrameEvent::kSuccess;
  const float d = target_distance(s);
  const float error = std::abs(wrap_angle(s.target_yaw - s.root.yaw));
  const float facing = 0.5f * (1.0f + std::cos(error));
  out.reward = std::exp(-d) + config_.facing_weight * std::exp(-d / config_.success_radius) * facing;
  if (out.success) {
    const float tolerance = std::max(config_.facing_tolerance, 1e-6f);
    const float precision = 0.5f * (std::max(0.0f, 1.0f - d / config_.success_radius) +
                                    std::max(0.0f, 1.0f - error / tolerance));
    out.reward += config_.success_bonus * (1.0f + config_.precision_weight * precision);
  }
  return out;
}

namespace {

// Seconds each frame of db goes on standing, and on standing still (0 for a frame that does not):
// one pair of tables per database, shared by every env's and character's rule while any lives (a
// crowd of 1,000 characters holds one).
struct StandingTables {
  std::vector<float> idle, still;  // kIdleMeters; kIdleMeters and kStillDegrees (features.hpp)
};

std::shared_ptr<const StandingTables> standing_seconds(const Database& db) {
  static std::mutex mutex;
  // Keyed by the database and its feature rows (a database freed and another built at its address
  // finds its table expired: a rule never outlives the database it borrows).
  static std::map<std::pair<const Database*, const float*>, std::weak_ptr<const StandingTables>> tables;
  const std::lock_guard<std::mutex> lock(mutex);
  for (auto it = tables.begin(); it != tables.end();) it = it->second.expired() ? tables.erase(it) : std::next(it);
  auto& slot = tables[{&db, db.features.data()}];
  const size_t n = static_cast<size_t>(db.num_frames);
  if (auto table = slot.lock(); table && table->idle.size() == n) return table;
  auto table = std::make_shared<StandingTables>();
  table->idle.assign(n, 0.0f);
  table->still.assign(n, 0.0f);
  const float lookahead = static_cast<float>(kTrajectoryOffsets[2]);
  for (int c = 0; c < db.num_clips(); ++c) {
    float idle_run = 0, still_run = 0, planted_run = 0;  // such frames from this one on, in this clip
    for (int r = db.clip_ranges[2 * c + 1] - 1; r >= db.clip_ranges[2 * c]; --r) {
      const size_t row = static_cast<size_t>(r);
      const float* f = &db.features[row * kFeatureDim];
      const bool idle = db.valid[row] && feature_row_idle(f);
      const bool still = idle && idle_row_stands_still(f);
      idle_run = idle ? idle_run + 1 : 0;
      still_run = still ? still_run + 1 : 0;
      if (idle) table->idle[row] = (idle_run - 1 + lookahead) / db.fps;
      planted_run = foot_planted(f + 6) && foot_planted(f + 9) ? planted_run + 1 : 0;
      // Standing still lasts until the idle ends or a foot lifts (a fidget, a weight shift).
      if (still) table->still[row] = std::min((still_run - 1 + lookahead) / db.fps, planted_run / db.fps);
    }
  }
  slot = table;
  return table;
}

class StandIdleRule final : public CandidateRule {
 public:
  StandIdleRule(const Database& db, const ArriveTaskConfig& config)
      : tables_(standing_seconds(db)), cost_(config.stand_idle_cost), horizon_(config.stand_idle_seconds) {}
  bool prepare(const RuleContext& context) override {
    // Facing within kStillTurn: long still idles; farther: idles that turn in place count too,
    // so the stand turns to its facing before it stands still.
    seconds_ = std::abs(context.stand_turn) <= kStillTurn ? &tables_->still : &tables_->idle;
    return context.standing;
  }

 protected:
  float cost(const Candidate& c) const override {
    if (c.row < 0) return 0.0f;
    const float t = (*seconds_)[static_cast<size_t>(c.row)];
    return t > 0 ? cost_ * std::max(0.0f, 1.0f - t / horizon_) : cost_;
  }

 private:
  static constexpr float kStillTurn = 5.0f * kPi / 180.0f;
  std::shared_ptr<const StandingTables> tables_;
  const std::vector<float>* seconds_ = nullptr;
  float cost_, horizon_;
};

}  // namespace

std::unique_ptr<CandidateRule> make_stand_idle_rule(const RuleSetup& setup) {
  const auto* config = dynamic_cast<const ArriveTaskConfig*>(&setup.config);
  if (!config || !(config->stand_idle_seconds > 0) || !(config->stand_idle_cost > 0)) return nullptr;
  return std::make_unique<StandIdleRule>(setup.db, *config);
}

void ArriveVecEnv::step(const float* actions, const TargetStepBuffers& out) { step_envs(actions, out, 4, [](int) {}); }

}  // namespace mmrl
