// The moving-obstacles task (paper, sections 4 and 5) on the batched target-reaching env
// (vecenv.hpp: pool, RNGs, valid frames, SAME_STEP autoreset, bookkeeping). This file holds
// the task's observation, its step and its scene (obstacles, sensor maps, hits).
//
// observation (kObsDim = 529 floats, flat):
//   [0, 256)    current sensor map, row-major [row][col] (grid.hpp: row along the
//               character's Z / forward, col along X / left), 0 or 1
//   [256, 512)  the previous RL step's map (at reset: a copy of the current map)
//   [512, 527)  c_t: normalized pose features of the current frame
//   [527, 529)  g_t: target (x, z) in the character frame, meters
//   i.e. maps as (channel, row, col) with channel 0 current, 1 previous.
//   With request_groups: the request's code last (vecenv.hpp's request_dim).
// action       12-d trajectory feature in normalized units, clipped to the box of
//              mean +- action_limit_std * std (as the plane task)
// reward       exp(-|g_t|) after the step
//              + exp(-hits) if hit_reward (hits: how many of the clipped action's three
//                positions, denormalized and placed in the world through the character
//                frame at the step's start, lie inside an obstacle at the step's start;
//                the paper's test. hit_radius > 0 tests a disc of that radius instead of
//                the point, and hit_lookahead tests position k against the obstacles as
//                they will be at its own time, 10 / 20 / 30 frames ahead). The term is
//                hit_weight * exp(-hits), minus hit_weight if hit_penalty (a penalty that
//                is 0 for a clear action: the paper's form also pays for every surviving step)
//              + success_bonus on success. The paper says both "10 rewards" on success
//                (section 4) and "no extra rewards" (section 5); the default is 10.
// terminated   success (root within success_radius of the target) or collision (the body
//              disc of body_radius around the root overlaps an obstacle), both tested on
//              every played frame after the obstacles and the root have moved one frame;
//              the first event ends the step (no later frame is played: step_frames
//              is that frame's index + 1); collision wins a tie.
// truncated    max_steps steps (the paper has no step limit; this cap only stops runaway
//              episodes: 1500 steps = 300 s, far longer than any reasonable path).
// Obstacles move every played frame (1 / fps s). The sensor square sits 1.5 m ahead by
// default (sensor_forward): the character moves forward almost always (the data has almost
// no turning in place or walking backwards), so 4.5 m ahead and 1.5 m behind (still
// covering the body and the sides during a turn) is worth more than 3 m behind.
//
// Broadphase: the grid (grid.hpp) is rebuilt every rebuild_interval() steps, with a margin
// covering the obstacles' motion over that many steps (about 0.4 m), never for static
// obstacles; every query is exact on the current positions.
//
// Curriculum: set_stage(max_speed, target_half_extent) stores the stage; each environment
// picks it up at its next reset (episodes in flight keep theirs).
#pragma once

#include <cstdint>
#include <vector>

#include "mmrl/compressed.hpp"  // kMlpMaxRows: compressed_path_fan's bound
#include "mmrl/grid.hpp"
#include "mmrl/tasks/path_filter.hpp"
#include "mmrl/vecenv.hpp"

namespace mmrl {

// The base's numbers (tasks/task_config.hpp; target_half_extent is the initial stage's) and
// the task's own, each with its range and doc in visit(). Defaults that differ from the base:
// success_bonus 10, max_steps 1500.
struct ObstacleTaskConfig : TaskConfig {
  ObstacleTaskConfig() {
    success_bonus = 10.0f;
    max_steps = 1500;
  }
  // docs/obstacles.md, "Retired options", says what each did and measured.
  static std::vector<RetiredOption> retired() {
    return {{"hit_played", 0, false}, {"bias_yields", 0}, {"observe_continuation", 0}, {"path_fan", 0},
            {"previous_map_lag", 1}};
  }
  float obstacle_max_speed = 0.5f;
  float speed_cap = 2.0f;
  bool hit_reward = true;
  float hit_weight = 1.0f;
  bool hit_penalty = false;
  float hit_radius = 0.0f;
  bool hit_lookahead = false;
  bool path_filter = false;
  float path_cost = 100.0f;
  int path_horizon = 30;
  float path_margin = 0.05f;
  int path_candidates = 16;
  float path_fan_degrees = 30.0f;
  int path_fan_candidates = 1;
  int path_escapes = 0;
  int compressed_path_fan = 3;
  int num_obstacles = 100;
  float obstacle_square_half = 10.0f;
  float obstacle_min_side = 0.25f;
  float obstacle_max_side = 3.0f;
  float body_radius = 0.25f;
  float start_clearance = 0.5f;
  float target_clearance = 0.5f;
  float sensor_size = 6.0f;
  float sensor_forward = 1.5f;
  float grid_cell_size = 1.5f;

  template <class Visit>
  static void visit(Visit&& v) {
    using C = ObstacleTaskConfig;
    visit_task_config_fields(v);
    v("obstacle_max_speed", &C::obstacle_max_speed, kNonNegative,
      "Stage before any set_stage: obstacle speeds uniform in [0, this] m/s (at most speed_cap).");
    v("speed_cap", &C::speed_cap, kNonNegative,
      "The largest max speed (m/s) set_stage accepts; sizes the collision grid's margin.");
    v("hit_reward", &C::hit_reward, kAny, "Add the hit term to the reward (false: the --no-hit-reward ablation).");
    v("hit_weight", &C::hit_weight, kNonNegative, "The hit term is hit_weight * exp(-hits) (the paper: 1).");
    v("hit_penalty", &C::hit_penalty, kAny,
      "Subtract hit_weight from the hit term: 0 for a clear action, so surviving is not paid.");
    v("hit_radius", &C::hit_radius, kNonNegative,
      "A trajectory point hits when a disc of this radius (meters) overlaps an obstacle; 0: the paper's point.");
    v("hit_lookahead", &C::hit_lookahead, kAny,
      "Test each trajectory point against the obstacles where they will be at its time (10/20/30 frames ahead).");
    v("path_filter", &C::path_filter, kAny,
      "The collision-aware search: every candidate's played path is tested against where the obstacles will be, "
      "and a path that hits costs more in the match (tasks/path_filter.hpp).");
    v("path_cost", &C::path_cost, OptionRange{0.0, kOptionInf, false, true},
      "Extra match cost of a path that hits at the horizon, twice that right away; inf: never play a path that "
      "hits unless every candidate does.");
    v("path_horizon", &C::path_horizon, closed_range(kPathSampleFrames[0], kPathSampleFrames[kPathSamples - 1]),
      "How far ahead (frames) the path filter tests a candidate's path.");
    v("path_margin", &C::path_margin, kNonNegative,
      "Added to body_radius for the path test (meters): covers the frames between the path's samples.");
    v("path_candidates", &C::path_candidates, closed_range(0, kMaxShortlist),
      "The path filter re-ranks this many nearest candidates of each decision (and the continuation); 0: the "
      "exact filtered search over the whole database (slow, for baselines).");
    v("path_fan_degrees", &C::path_fan_degrees, OptionRange{0.0, 90.0, true},
      "The turn between a compressed controller's turned queries (degrees; compressed_path_fan).");
    v("path_fan_candidates", &C::path_fan_candidates, closed_range(1, kMaxShortlist),
      "How many nearest candidates each escape query adds to the shortlist.");
    v("path_escapes", &C::path_escapes, closed_range(0, kMaxEscapes),
      "Escape queries of the path filter's shortlist: the pose shown asking to stand (1), to step back, left and "
      "right (2-4; 0.5 m/s), to walk towards 0, +-45, +-90, +-135 and 180 degrees (5-12; 1 m/s) and to run the "
      "same ways (13-20; 2 m/s), add path_fan_candidates nearest frames each (found once per database frame), so "
      "ways to wait, give way and go round join the shortlist.");
    v("compressed_path_fan", &C::compressed_path_fan, closed_range(0, (kMlpMaxRows - 1) / 2),
      "A compressed controller under the path filter: the projections of the query and of the query turned by "
      "+-1..n x path_fan_degrees are its candidates (docs/compressed.md).");
    v("num_obstacles", &C::num_obstacles, closed_range(0, 30000), "Rectangles per environment.");
    v("obstacle_square_half", &C::obstacle_square_half, kPositive,
      "Obstacle centres start uniform in, and bounce inside, a square of side 2 * this (meters) around the start.");
    v("obstacle_min_side", &C::obstacle_min_side, kPositive,
      "Each rectangle side is uniform in [obstacle_min_side, obstacle_max_side] meters.");
    v("obstacle_max_side", &C::obstacle_max_side, kPositive, "Largest rectangle side (meters); the paper's 3 m.");
    v("body_radius", &C::body_radius, kNonNegative, "Collision disc around the root (meters).");
    v("start_clearance", &C::start_clearance, kNonNegative,
      "No obstacle starts within body_radius + this (meters) of the character.");
    v("target_clearance", &C::target_clearance, kNonNegative, "No obstacle starts within this (meters) of the target.");
    v("sensor_size", &C::sensor_size, kPositive, "Side of the square sensor map (meters), 16 x 16 point sensors.");
    v("sensor_forward", &C::sensor_forward, kAny,
      "Centre of the sensor square ahead of the root (meters); 0 centres it on the character.");
    v("grid_cell_size", &C::grid_cell_size, kPositive,
      "Cell side (meters) of the uniform grid used for sensors, hits and collisions.");
  }
};

struct ObstacleEnvState : TargetEnvState {
  // The stage this episode runs with.
  float max_speed = 0, target_half_extent = 0;
  // The last step's hits: the action's three tested trajectory positions in world (x, z) and
  // which were inside.
  int last_hits = 0;
  float hit_points[6] = {0, 0, 0, 0, 0, 0};
  uint8_t hit_inside[3] = {0, 0, 0};
  bool collided = false;
  int grid_age = 0;  // RL steps since env's grid was rebuilt
  int map_head = 0;  // slot (0 or 1) of the current sensor map; the previous one is in the other
};

class ObstacleTask : public TargetTask<ObstacleTask, ObstacleTaskConfig, ObstacleEnvState> {
 public:
  static constexpr int kMapOffset = 0;
  static constexpr int kPrevMapOffset = kMapCells;
  static constexpr int kPoseOffset = 2 * kMapCells;
  static constexpr int kGoalOffset = kPoseOffset + kPoseDim;
  static constexpr int kObsDim = kGoalOffset + 2;  // the paper's observation
  int obs_dim() const { return kObsDim + request_dim(); }  // with request_groups: the request's code last
  ObsLayout task_obs_layout() const { return {{"maps", 2 * kMapCells, ""}, {"pose", kPoseDim, ""}, {"goal", 2, ""}}; }
  static constexpr int kActionDim = kTrajectoryDim;
  static constexpr bool kStepEndsAtEvent = true;  // no frame plays after a success or a collision
  static constexpr const char* kCoreName = "obstacles";  // the name a controller file gives this core

  // db and matcher are borrowed and must outlive the task. Throws std::invalid_argument on a
  // bad config.
  ObstacleTask(const Database& db, const Matcher& matcher, int num_envs, const ObstacleTaskConfig& config);

  // The stage for every environment's next reset. 0 <= max_speed <= speed_cap,
  // target_half_extent > min_target_distance.
  void set_stage(float max_speed, float target_half_extent);
  float stage_max_speed() const { return stage_max_speed_; }
  float stage_target_half_extent() const { return stage_half_extent_; }

  void observe(int i, float* obs_row) const;
  const ObstacleField& field() const { return field_; }
  const uint8_t* sensor_map(int i) const { return map_slot(i, envs_[i].map_head); }
  const uint8_t* previous_sensor_map(int i) const { return map_slot(i, envs_[i].map_head ^ 1); }
  // Env i's map now with every sensor tested against every obstacle (the tests' reference),
  // kMapCells bytes [row][col].
  void sensor_map_bruteforce(int i, uint8_t* map) const;
  // World (x, z) of env i's sensors now, kMapSide x kMapSide x 2 floats [row][col].
  void sensor_positions(int i, float* out) const;
  // Whether env i's body disc (body_radius) at world (x, z) overlaps one of its obstacles.
  bool collides(int i, float x, float z) const;

  // Counts hits of an action (12 normalized floats, clipped like a step's) for env i's
  // current state; writes the three world points and inside flags if given.
  int action_hits(int i, const float* action, float* points = nullptr, uint8_t* inside = nullptr) const;
  // Counts hits of a raw trajectory (12 floats: meters and unit directions in env i's current
  // character frame), as action_hits does after denormalizing.
  int trajectory_hits(int i, const float* raw, float* points = nullptr, uint8_t* inside = nullptr) const;

  // The collision-aware search's test (tasks/path_filter.hpp, with this env's path options,
  // whether or not path_filter is on) of env i's current state: for each of n database rows,
  // the frames ahead of its path's first hit (kPathSampleFrames), or 0 when clear.
  void path_hits(int i, const int64_t* rows, int n, int32_t* first_hit_frames);
  // The same for n compressed states known by their features (n x kFeatureDim normalized
  // floats, finite) of env i's compressed controller (set_source first): each path is
  // trajectory_path of the state's trajectory (path_filter.hpp).
  void state_path_hits(int i, const float* features, int n, int32_t* first_hit_frames);

  // Env i's obstacles now (world meters, radians, m/s; see grid.hpp): centres and velocities
  // (n x 2, (x, z)), half sizes (n x 2, along the obstacle's own X / Z), angles (n). n is
  // obstacle_count(i); any output may be null.
  int obstacle_count(int i) const { return field_.count(i); }
  void obstacles(int i, float* centres, float* half_sizes, float* angles, float* velocities) const;
  // Env i's obstacle centres and velocities (n x 2 each) after `frames` more played frames
  // (frames >= 0) of the env's own motion (grid.hpp: constant velocity, bounce at the
  // square's border), as a step would move them: called at a step's start, frames =
  // step_frames gives the positions at the step's end. Sizes and angles do not change.
  void obstacles_after(int i, int frames, float* centres, float* velocities) const;

  // Scene editing (tests, evaluation, rendering). set_root and set_obstacles rebuild the
  // grid and recompute the sensor map; both maps become the new one, as at a reset.
  // set_target (TargetTask) changes no map. Bad values throw std::invalid_argument
  // naming the argument.
  void set_root(int i, float x, float z, float yaw);
  // centres, half_sizes, velocities: n x 2; angles: n; 0 <= n <= num_obstacles; all finite,
  // half sizes in [0, obstacle_max_side / 2], centres in the obstacle square, speeds <= speed_cap.
  void set_obstacles(int i, int n, const float* centres, const float* half_sizes, const float* angles,
                     const float* velocities);

  // How a scene given from outside updates env i's sensor maps (set_scene).
  enum class MapUpdate {
    kReset,    // both maps become the new one (a first decision, as at a reset)
    kPush,     // the current map becomes the previous one and the new one is current (a new decision)
    kReplace,  // the current map is recomputed in place (observing again before the same decision)
  };
  // The engine runtime's input to a decision: env i's character on database `frame` facing yaw
  // at the centre of its obstacle square (the origin: obstacles are given relative to the
  // character, as set_obstacles takes them), its target relative to it (meters), and its
  // obstacles. Then observe(i) and decide(i) are the training env's own. With a compressed
  // controller, frame -1 keeps env i's compressed state (set_state's rule). Bad values throw
  // std::invalid_argument as set_obstacles and set_state do.
  void set_scene(int i, int64_t frame, float yaw, float target_x, float target_z, int n, const float* centres,
                 const float* half_sizes, const float* angles, const float* velocities, MapUpdate maps);

 private:
  friend class TargetTask<ObstacleTask, ObstacleTaskConfig, ObstacleEnvState>;
  // After set_state: rebuild the grid and both sensor maps around the new root.
  void on_state_set(int i) { refresh(i, false, true); }
  // After the motion source changed (set_source): path_hits' filters are ready for its
  // candidates, and the maps follow the new state.
  void on_source_set() {
    for (ObstaclePathFilter& f : path_filters_) f.set_prices_states(source().rowless_candidates());
    for (int i = 0; i < num_envs(); ++i) refresh(i, false, true);
  }
  // Env i's obstacles for its next decision's rules (the path filter reads them).
  const ObstacleScene* scene(int i) {
    const ObstacleEnvState& s = envs_[i];
    scenes_[static_cast<size_t>(i)] = ObstacleScene{&field_, i, s.root, s.max_speed > 0, frame_dt_};
    return &scenes_[static_cast<size_t>(i)];
  }
  void begin_episode(int i);
  void begin_step(int i, const float* action);
  FrameEvent played_frame(int i, const RootState& before);
  TaskStep end_step(int i, FrameEvent event);
  // Steps between grid rebuilds for env i, and the margin that keeps the grid exact over them.
  int rebuild_interval(int i) const;
  float margin(int i) const;
  // Rebuilds the grid if forced or due, then recomputes the sensor map (keep_previous: the
  // old current map becomes the previous one; else both are the new map).
  void refresh(int i, bool keep_previous, bool force_rebuild) {
    refresh(i, keep_previous ? MapUpdate::kPush : MapUpdate::kReset, force_rebuild);
  }
  void refresh(int i, MapUpdate maps, bool force_rebuild);
  // set_obstacles' checks and the field update; returns the fastest obstacle's speed.
  float put_obstacles(int i, int n, const float* centres, const float* half_sizes, const float* angles,
                      const float* velocities);

  ObstacleField field_;
  std::vector<ObstacleScene> scenes_;             // per env: what scene(i) gave its rules last
  std::vector<ObstaclePathFilter> path_filters_;  // per env: path_hits' and state_path_hits' tests
  const uint8_t* map_slot(int i, int k) const {
    return &maps_[(static_cast<size_t>(i) * 2 + k) * kMapCells];
  }
  uint8_t* map_slot(int i, int k) { return &maps_[(static_cast<size_t>(i) * 2 + k) * kMapCells]; }
  std::vector<uint8_t> maps_;  // per env: two maps, the current one in slot map_head, the previous one in the other
  float stage_max_speed_, stage_half_extent_;
  float frame_dt_;
};

// The obstacles task's batched environments (vecenv.hpp's pool); a step also reports each
// env's collision and hits.
class ObstacleVecEnv : public TargetVecEnv<ObstacleTask> {
 public:
  using TargetVecEnv::TargetVecEnv;
  // actions: N x 12 (finite; checked by the caller). final_obs, episode_return and
  // episode_length rows are written only where an episode ended.
  void step(const float* actions, float* obs, float* rewards, uint8_t* terminated, uint8_t* truncated,
            uint8_t* success, uint8_t* collision, int32_t* hits, float* final_obs, float* episode_return,
            int32_t* episode_length);
  // The same with the shared outputs in one record (and its optional per-step rows, vecenv.hpp).
  void step(const float* actions, const TargetStepBuffers& out, uint8_t* collision, int32_t* hits);
};

}  // namespace mmrl
