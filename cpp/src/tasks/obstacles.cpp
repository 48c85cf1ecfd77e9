#include "mmrl/tasks/obstacles.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

namespace mmrl {

namespace {

// How far (meters) obstacles may travel between grid rebuilds (at least one step's travel).
constexpr float kRebuildTravel = 0.4f;
constexpr int kMaxRebuildInterval = 16;

// Validates the task config and derives the obstacle field's config from it.
ObstacleFieldConfig field_config(const Database& db, const ObstacleTaskConfig& c) {
  // Every option's range is checked by the task template (check_options); the rules between them here.
  if (!(c.obstacle_max_speed <= c.speed_cap))
    throw std::invalid_argument("obstacle_max_speed must be in [0, speed_cap], got " + std::to_string(c.obstacle_max_speed) +
                                " with speed_cap " + std::to_string(c.speed_cap));
  if (!(c.obstacle_min_side <= c.obstacle_max_side))
    throw std::invalid_argument("obstacle_min_side must be <= obstacle_max_side, got " +
                                std::to_string(c.obstacle_min_side) + " > " + std::to_string(c.obstacle_max_side));
  if (!(db.fps > 0)) throw std::invalid_argument("database fps must be positive");
  // A body that does not fit in the sensor map's half or the obstacle square cannot be steered
  // by what it senses: refuse such a task rather than train on it.
  const float body = c.body_radius + (c.path_filter ? c.path_margin : 0.0f);
  if (!(body < 0.5f * c.sensor_size) || !(body < c.obstacle_square_half))
    throw std::invalid_argument(std::string(c.path_filter ? "body_radius + path_margin" : "body_radius") + " (" +
                                std::to_string(body) + " m) must be smaller than half the sensor map (sensor_size / 2 = " +
                                std::to_string(0.5f * c.sensor_size) + " m) and the obstacle square (" +
                                "obstacle_square_half = " + std::to_string(c.obstacle_square_half) + " m)");
  ObstacleFieldConfig f;
  f.num_obstacles = c.num_obstacles;
  f.square_half = c.obstacle_square_half;
  f.min_side = c.obstacle_min_side;
  f.max_side = c.obstacle_max_side;
  f.cell_size = c.grid_cell_size;
  f.max_margin = c.body_radius + std::max(kRebuildTravel, c.speed_cap * static_cast<float>(c.frames_per_step) / db.fps) +
                 0.01f;
  f.sensor_size = c.sensor_size;
  f.sensor_forward = c.sensor_forward;
  return f;
}

PathFilterConfig path_filter_config(const ObstacleTaskConfig& c) {
  PathFilterConfig pc;
  pc.radius = c.body_radius + c.path_margin;
  pc.cost = c.path_cost;
  pc.horizon = c.path_horizon;
  return pc;
}

}  // namespace

std::unique_ptr<CandidateRule> make_path_filter_rule(const RuleSetup& setup) {
  const auto* c = dynamic_cast<const ObstacleTaskConfig*>(&setup.config);
  if (!c || !c->path_filter) return nullptr;
  auto rule = std::make_unique<ObstaclePathFilter>();
  rule->init(setup.db, c->num_obstacles, path_filter_config(*c));
  std::shared_ptr<const EscapeTable> escapes;
  if (c->path_candidates > 0 && c->path_escapes > 0) {
    if (c->path_escapes * c->path_fan_candidates > kMaxExtraRows)
      throw std::invalid_argument("path_escapes x path_fan_candidates must be at most " +
                                  std::to_string(kMaxExtraRows) + ", got " + std::to_string(c->path_escapes) +
                                  " x " + std::to_string(c->path_fan_candidates));
    escapes = EscapeTable::shared(setup.db, setup.matcher, c->path_escapes, c->path_fan_candidates);
  }
  rule->set_shortlist({c->path_candidates, 0, 0.0f, c->path_fan_candidates, c->path_escapes, nullptr},
                      {0, c->compressed_path_fan, deg_to_rad(c->path_fan_degrees), 1}, std::move(escapes));
  return rule;
}

ObstacleTask::ObstacleTask(const Database& db, const Matcher& matcher, int num_envs, const ObstacleTaskConfig& config)
    : TargetTask(db, matcher, num_envs, config),
      field_(num_envs, field_config(db, config)),
      maps_(static_cast<size_t>(num_envs) * 2 * kMapCells, 0),
      stage_max_speed_(config.obstacle_max_speed),
      stage_half_extent_(config.target_half_extent),
      frame_dt_(1.0f / db.fps) {
  scenes_.resize(static_cast<size_t>(num_envs));
  path_filters_.resize(static_cast<size_t>(num_envs));
  for (ObstaclePathFilter& f : path_filters_) f.init(db, config.num_obstacles, path_filter_config(config));
}

void ObstacleTask::path_hits(int i, const int64_t* rows, int n, int32_t* first_hit_frames) {
  for (int k = 0; k < n; ++k)
    if (rows[k] < 0 || rows[k] >= db_.num_frames || !db_.valid[rows[k]])
      throw std::invalid_argument("rows: " + std::to_string(rows[k]) + " is not a valid database frame");
  const ObstacleEnvState& s = envs_[i];
  ObstaclePathFilter& f = path_filters_[i];
  f.prepare(field_, i, s.root, s.max_speed > 0, frame_dt_);
  for (int k = 0; k < n; ++k) {
    const int hit = f.first_hit(rows[k]);
    first_hit_frames[k] = hit < 0 ? 0 : kPathSampleFrames[hit];
  }
}

void ObstacleTask::state_path_hits(int i, const float* features, int n, int32_t* first_hit_frames) {
  if (!source().rowless_candidates())
    throw std::invalid_argument("state_path_hits: no compressed controller is set (the env plays the database)");
  for (int64_t k = 0; k < static_cast<int64_t>(n) * kFeatureDim; ++k)
    if (!std::isfinite(features[k])) throw std::invalid_argument("features must be finite");
  const ObstacleEnvState& s = envs_[i];
  ObstaclePathFilter& f = path_filters_[i];
  f.prepare(field_, i, s.root, s.max_speed > 0, frame_dt_);
  for (int k = 0; k < n; ++k) {
    const int hit = f.first_hit_state(features + static_cast<size_t>(k) * kFeatureDim);
    first_hit_frames[k] = hit < 0 ? 0 : kPathSampleFrames[hit];
  }
}

void ObstacleTask::set_stage(float max_speed, float target_half_extent) {
  if (!(max_speed >= 0) || !(max_speed <= config_.speed_cap))
    throw std::invalid_argument("max_speed must be in [0, speed_cap = " + std::to_string(config_.speed_cap) + "]");
  if (!(target_half_extent > config_.min_target_distance) || !std::isfinite(target_half_extent))
    throw std::invalid_argument("target_half_extent must be finite and larger than min_target_distance");
  stage_max_speed_ = max_speed;
  stage_half_extent_ = target_half_extent;
}

int ObstacleTask::rebuild_interval(int i) const {
  const float step_travel = envs_[i].max_speed * static_cast<float>(config_.frames_per_step) * frame_dt_;
  if (!(step_travel > 0)) return 1 << 30;  // static obstacles: the reset's grid stays exact
  return std::max(1, std::min(kMaxRebuildInterval, static_cast<int>(kRebuildTravel / step_travel)));
}

float ObstacleTask::margin(int i) const {
  const float step_travel = envs_[i].max_speed * static_cast<float>(config_.frames_per_step) * frame_dt_;
  const int interval = rebuild_interval(i);
  return config_.body_radius + (step_travel > 0 ? step_travel * static_cast<float>(interval) : 0.0f) + 0.005f;
}

void ObstacleTask::refresh(int i, MapUpdate maps, bool force_rebuild) {
  ObstacleEnvState& st = envs_[i];
  if (force_rebuild || st.grid_age >= rebuild_interval(i)) {
    field_.rebuild(i, margin(i));
    st.grid_age = 0;
  }
  // Two maps: a new one overwrites the previous RL step's slot and becomes the current one. A
  // reset (and hand-set scenes) gives both slots the new map.
  if (maps == MapUpdate::kPush) st.map_head ^= 1;
  uint8_t* cur = map_slot(i, st.map_head);
  field_.sensor_map(i, st.root.x, st.root.z, st.root.yaw, cur);
  if (maps == MapUpdate::kReset) std::copy(cur, cur + kMapCells, map_slot(i, st.map_head ^ 1));
}

void ObstacleTask::observe(int i, float* obs) const {
  const ObstacleEnvState& s = envs_[i];
  const uint8_t* cur = sensor_map(i);
  const uint8_t* prev = previous_sensor_map(i);
  for (int k = 0; k < kMapCells; ++k) obs[kMapOffset + k] = cur[k];
  for (int k = 0; k < kMapCells; ++k) obs[kPrevMapOffset + k] = prev[k];
  observe_pose(s, obs + kPoseOffset);
  observe_goal(s, obs + kGoalOffset);
  observe_request(i, obs + kObsDim);
}

void ObstacleTask::begin_episode(int i) {
  ObstacleEnvState& s = envs_[i];
  s.max_speed = stage_max_speed_;
  s.target_half_extent = stage_half_extent_;
  draw_start(i, s.target_half_extent);
  const ClearDisc clear[2] = {{0.0f, 0.0f, config_.body_radius + config_.start_clearance},
                              {s.target_x, s.target_z, config_.target_clearance}};
  field_.spawn(i, s.rng, s.max_speed, clear, 2);
  s.last_hits = 0;
  std::fill(s.hit_points, s.hit_points + 6, 0.0f);
  std::fill(s.hit_inside, s.hit_inside + 3, uint8_t{0});
  s.collided = false;
  refresh(i, false, true);
}

int ObstacleTask::action_hits(int i, const float* action, float* points, uint8_t* inside) const {
  float clipped[kTrajectoryDim], raw[kTrajectoryDim];
  const float* low = action_low();
  const float* high = action_high();
  for (int k = 0; k < kTrajectoryDim; ++k) clipped[k] = std::min(high[k], std::max(low[k], action[k]));
  trajectory_denormalize(db_, clipped, raw);
  return trajectory_hits(i, raw, points, inside);
}

int ObstacleTask::trajectory_hits(int i, const float* raw, float* points, uint8_t* inside) const {
  const ObstacleEnvState& s = envs_[i];
  int hits = 0;
  for (int k = 0; k < 3; ++k) {
    // Layout (features.hpp): per horizon, position (x, z) then direction (x, z).
    const Vec2 w = local_to_world_xz(raw[4 * k], raw[4 * k + 1], s.root.yaw);
    const float x = s.root.x + w.x(), z = s.root.z + w.y();
    // The grid's margin covers body_radius, so a wider disc or a look ahead tests every obstacle.
    const float dt = static_cast<float>(kTrajectoryOffsets[k]) / db_.fps;
    const bool in = (config_.hit_lookahead || config_.hit_radius > config_.body_radius)
                        ? field_.disc_overlaps_any_ahead(i, x, z, config_.hit_radius, config_.hit_lookahead ? dt : 0.0f)
                        : field_.disc_overlaps_any(i, x, z, config_.hit_radius);
    hits += in;
    if (points) points[2 * k] = x, points[2 * k + 1] = z;
    if (inside) inside[k] = in;
  }
  return hits;
}

void ObstacleTask::begin_step(int i, const float* action) {
  // The hit test uses the root and the obstacles at the step's start, before anything moves.
  ObstacleEnvState& s = envs_[i];
  s.last_hits = action_hits(i, action, s.hit_points, s.hit_inside);
}

FrameEvent ObstacleTask::played_frame(int i, const RootState&) {
  // The obstacles move with every played frame; then the body and the target are tested where
  // both are now (a collision wins a tie).
  const ObstacleEnvState& s = envs_[i];
  if (s.max_speed > 0) field_.move(i, frame_dt_);
  if (field_.disc_overlaps_any(i, s.root.x, s.root.z, config_.body_radius)) return FrameEvent::kFailure;
  return within_success_radius(s) ? FrameEvent::kSuccess : FrameEvent::kNone;
}

TaskStep ObstacleTask::end_step(int i, FrameEvent event) {
  ObstacleEnvState& s = envs_[i];
  s.collided = event == FrameEvent::kFailure;
  TaskStep out;
  out.success = event == FrameEvent::kSuccess;
  out.terminated = event != FrameEvent::kNone;
  out.reward = std::exp(-target_distance(s));
  if (config_.hit_reward)
    out.reward += config_.hit_weight * (std::exp(-static_cast<float>(s.last_hits)) - (config_.hit_penalty ? 1.0f : 0.0f));
  if (out.success) out.reward += config_.success_bonus;
  // The observation after the step: the grid when due, and the sensor map at the new root.
  s.grid_age += 1;
  refresh(i, true, false);
  return out;
}

void ObstacleVecEnv::step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
                          uint8_t* success, uint8_t* collision, int32_t* hits, float* final_obs,
                          float* episode_return, int32_t* episode_length) {
  step(actions, TargetStepBuffers{obs, rewards, terminated, truncated, success, final_obs, episode_return,
                                  episode_length},
       collision, hits);
}

void ObstacleVecEnv::step(const float* actions, const TargetStepBuffers& out, uint8_t* collision, int32_t* hits) {
  step_envs(actions, out, 2, [&](int i) {
    collision[i] = envs_[i].collided;
    hits[i] = envs_[i].last_hits;
  });
}

void ObstacleTask::sensor_map_bruteforce(int i, uint8_t* map) const {
  const ObstacleEnvState& s = envs_[i];
  field_.sensor_map_bruteforce(i, s.root.x, s.root.z, s.root.yaw, map);
}

void ObstacleTask::sensor_positions(int i, float* out) const {
  const ObstacleEnvState& s = envs_[i];
  for (int r = 0; r < kMapSide; ++r)
    for (int c = 0; c < kMapSide; ++c) {
      const Vec2 p = field_.sensor_position(s.root.x, s.root.z, s.root.yaw, r, c);
      out[(r * kMapSide + c) * 2] = p.x();
      out[(r * kMapSide + c) * 2 + 1] = p.y();
    }
}

bool ObstacleTask::collides(int i, float x, float z) const {
  if (!std::isfinite(x) || !std::isfinite(z)) throw std::invalid_argument("position must be finite");
  return field_.disc_overlaps_any(i, x, z, config_.body_radius);
}

void ObstacleTask::obstacles(int i, float* centres, float* half_sizes, float* angles, float* velocities) const {
  for (int k = 0; k < field_.count(i); ++k) {
    if (centres) centres[2 * k] = field_.centre(i, k).x(), centres[2 * k + 1] = field_.centre(i, k).y();
    if (half_sizes) half_sizes[2 * k] = field_.half_size(i, k).x(), half_sizes[2 * k + 1] = field_.half_size(i, k).y();
    if (angles) angles[k] = field_.angle(i, k);
    if (velocities) velocities[2 * k] = field_.velocity(i, k).x(), velocities[2 * k + 1] = field_.velocity(i, k).y();
  }
}

void ObstacleTask::obstacles_after(int i, int frames, float* centres, float* velocities) const {
  if (frames < 0) throw std::invalid_argument("frames must be >= 0");
  // Static episodes never move (played_frame skips move() when the stage's max speed is 0).
  field_.moved(i, envs_[i].max_speed > 0 ? frames : 0, frame_dt_, centres, velocities);
}

void ObstacleTask::set_root(int i, float x, float z, float yaw) {
  if (!std::isfinite(x) || !std::isfinite(z) || !std::isfinite(yaw)) throw std::invalid_argument("root must be finite");
  envs_[i].root.x = x;
  envs_[i].root.z = z;
  envs_[i].root.yaw = wrap_angle(yaw);
  refresh(i, false, true);
}

namespace {

void check_finite(const float* v, int n, const char* name) {
  for (int k = 0; k < n; ++k)
    if (!std::isfinite(v[k]))
      throw std::invalid_argument(std::string(name) + ": contains NaN or inf (at flat index " + std::to_string(k) + ")");
}

}  // namespace

void ObstacleTask::set_obstacles(int i, int n, const float* centres, const float* half_sizes, const float* angles,
                                   const float* velocities) {
  envs_[i].max_speed = put_obstacles(i, n, centres, half_sizes, angles, velocities);
  refresh(i, MapUpdate::kReset, true);
}

void ObstacleTask::set_scene(int i, int64_t frame, float yaw, float target_x, float target_z, int n,
                               const float* centres, const float* half_sizes, const float* angles,
                               const float* velocities, MapUpdate maps) {
  // set_state's rule: frame -1 keeps a compressed state.
  if (!source_->starts_at(frame)) throw std::invalid_argument("frame is outside the database");
  if (!std::isfinite(yaw)) throw std::invalid_argument("yaw must be finite");
  set_target(i, target_x, target_z);
  const float fastest = put_obstacles(i, n, centres, half_sizes, angles, velocities);
  ObstacleEnvState& s = envs_[i];
  source_->start(s, frame);
  s.root = RootState{0.0f, 0.0f, wrap_angle(yaw)};
  s.max_speed = fastest;
  refresh(i, maps, true);
}

float ObstacleTask::put_obstacles(int i, int n, const float* centres, const float* half_sizes, const float* angles,
                                    const float* velocities) {
  if (n < 0 || n > config_.num_obstacles)
    throw std::invalid_argument("centres: at most num_obstacles = " + std::to_string(config_.num_obstacles) +
                                " obstacles, got " + std::to_string(n));
  check_finite(centres, 2 * n, "centres");
  check_finite(half_sizes, 2 * n, "half_sizes");
  check_finite(angles, n, "angles");
  check_finite(velocities, 2 * n, "velocities");
  for (int k = 0; k < 2 * n; ++k)
    if (!(half_sizes[k] >= 0)) throw std::invalid_argument("half_sizes: must be >= 0");
  // The margin follows the fastest given obstacle, so moving hand-built scenes stay exact.
  float fastest = 0;
  for (int k = 0; k < n; ++k) fastest = std::max(fastest, std::hypot(velocities[2 * k], velocities[2 * k + 1]));
  if (fastest > config_.speed_cap) throw std::invalid_argument("velocities: obstacle speed exceeds speed_cap");
  field_.set(i, n, centres, half_sizes, angles, velocities);
  return fastest;
}

}  // namespace mmrl
