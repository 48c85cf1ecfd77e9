#include "mmrl/runtime.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "mmrl/database_io.hpp"
#include "mmrl/tags.hpp"

namespace mmrl {

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The database sections -> DatabaseState (database_from_state checks every shape).
DatabaseState database_state(const ControllerFile& f) {
  DatabaseState s;
  // A section as a StateArray with its stored shape.
  auto arr = [&](auto values, const char* name) {
    using T = typename decltype(values)::value_type;
    return StateArray<T>{std::move(values), f.section(name).shape};
  };
  auto floats = [&](const char* name) { return arr(f.floats(name), name); };
  auto ints = [&](const char* name) { return arr(f.ints(name), name); };
  auto bytes = [&](const char* name) { return arr(f.bytes(name), name); };
  s.joint_names = f.texts("db.joint_names");
  s.channels = f.texts("db.channels");
  s.clip_names = f.texts("db.clip_names");
  s.parents = ints("db.parents");
  s.offsets = floats("db.offsets");
  s.end_sites = floats("db.end_sites");
  s.has_end_site = bytes("db.has_end_site");
  const auto roles = f.ints("db.roles", {9});
  s.roles.assign(roles.begin(), roles.end());
  const auto scalars = f.floats("db.scalars", {2});
  s.fps = scalars[0];
  s.source_scale = scalars[1];
  s.clip_ranges = ints("db.clip_ranges");
  s.clip_mirrored = bytes("db.clip_mirrored");
  if (f.has("db.tag_names")) {  // tags (optional; tags.hpp)
    s.tag_names = f.texts("db.tag_names");
    s.clip_tags = bytes("db.clip_tags");
  }
  s.bone_translations = floats("db.bone_translations");
  s.bone_rotations = floats("db.bone_rotations");
  s.root_positions = floats("db.root_positions");
  s.root_yaws = floats("db.root_yaws");
  s.root_deltas = floats("db.root_deltas");
  s.features = floats("db.features");
  s.contacts = bytes("db.contacts");
  s.feature_mean = floats("db.feature_mean");
  s.block_scale = floats("db.block_scale");
  s.weights = floats("db.weights");
  return s;
}

std::map<std::string, double> numbers(const ControllerFile& f, const std::string& prefix) {
  const auto keys = f.texts(prefix + ".keys");
  const auto values = f.doubles(prefix + ".values", {static_cast<int64_t>(keys.size())});
  std::map<std::string, double> out;
  for (size_t k = 0; k < keys.size(); ++k) {
    // +inf is a value only where a config means "never" by it (path_cost: never play a path that hits).
    const bool inf_ok = prefix == "task" && keys[k] == "path_cost" && values[k] == HUGE_VAL;
    if (!std::isfinite(values[k]) && !inf_ok) f.fail("'" + prefix + "." + keys[k] + "' is not finite");
    out[keys[k]] = values[k];
  }
  return out;
}

double number(const ControllerFile& f, const std::map<std::string, double>& m, const std::string& prefix,
              const std::string& key) {
  const auto it = m.find(key);
  if (it == m.end()) f.fail("section '" + prefix + ".keys' lacks '" + key + "'");
  return it->second;
}

// The config of a task core from the file's task numbers (by Config::visit's field names;
// a field the file lacks keeps its default) and its optional clip costs.
template <class Config>
Config task_config(const ControllerFile& f, const RuntimeTask& t, int64_t num_clips) {
  Config c;
  Config::visit([&](const char* name, auto member) {
    using T = typename std::decay<decltype(c.*member)>::type;
    if constexpr (std::is_same<T, std::vector<float>>::value) {
      const std::string section = std::string("task.") + name;
      if (f.has(section)) c.*member = f.floats(section, {num_clips});
    } else if constexpr (std::is_same<T, std::vector<std::string>>::value) {
      const std::string section = std::string("task.") + name;
      if (f.has(section)) c.*member = f.texts(section);
    } else {
      const auto it = t.values.find(name);
      if (it == t.values.end()) return;
      if (std::is_integral<T>::value && !std::is_same<T, bool>::value &&
          (it->second != std::floor(it->second) || std::abs(it->second) > 1e9))
        f.fail(std::string("task.") + name + " must be a whole number");
      c.*member = static_cast<T>(it->second);
    }
  });
  return c;
}

RuntimeTask read_task(const ControllerFile& f, int obs_dim, const Database& db) {
  const int64_t num_clips = db.num_clips();
  RuntimeTask t;
  const auto names = f.texts("task.name");
  if (names.size() != 1) f.fail("section 'task.name' must hold one name");
  t.name = names[0];
  t.values = numbers(f, "task");
  for (const char* key : {"frames_per_step", "action_limit_std", "transition_cost", "success_radius"})
    number(f, t.values, "task", key);  // required
  // The core the task runs on: named by the file (task.core), else (older files) the task's
  // own name when it is a core's, else told by the policy's observation size.
  if (f.has("task.core")) {
    const auto core = f.texts("task.core");
    if (core.size() != 1) f.fail("section 'task.core' must hold one name");
    t.core = core[0];
  } else if (t.name == PlaneVecEnv::kCoreName || t.name == ObstacleVecEnv::kCoreName) {
    t.core = t.name;
  } else {
    t.core = obs_dim == ObstacleVecEnv::kObsDim ? ObstacleVecEnv::kCoreName : PlaneVecEnv::kCoreName;
  }
  const bool plane = t.core == PlaneVecEnv::kCoreName;
  t.obstacles = t.core == ObstacleVecEnv::kCoreName;
  if (!plane && !t.obstacles)
    f.fail("task.core '" + t.core + "' is not a core this runtime has (plane, obstacles)");
  t.plane = task_config<PlaneTaskConfig>(f, t, num_clips);
  t.obstacle = task_config<ObstacleTaskConfig>(f, t, num_clips);
  const bool continuation = t.obstacles && t.obstacle.observe_continuation;
  const std::vector<std::string>& groups = plane ? t.plane.request_groups : t.obstacle.request_groups;
  int request_dim = 0;
  try {
    request_dim = RequestCode(db, groups).dim();
  } catch (const std::invalid_argument& e) {
    f.fail(std::string("task.request_groups: ") + e.what());
  }
  const int want = (plane ? PlaneVecEnv::kObsDim
                          : ObstacleVecEnv::kObsDim + (continuation ? ObstacleVecEnv::kContinuationDim : 0)) +
                   request_dim;
  if (obs_dim != want)
    f.fail("the policy reads " + std::to_string(obs_dim) + " observations; the " + t.core + " task's are " +
           std::to_string(want) +
           (t.obstacles ? std::string(" (task.observe_continuation ") + (continuation ? "on" : "off") + ")" : "") +
           (request_dim ? " with a request code of " + std::to_string(request_dim) : ""));
  const TaskConfig& base = plane ? static_cast<const TaskConfig&>(t.plane) : t.obstacle;
  t.frames_per_step = base.frames_per_step;
  t.success_radius = base.success_radius;
  if (t.obstacles && t.obstacle.path_filter) {  // the collision-aware search needs its numbers
    for (const char* key : {"path_cost", "path_horizon", "path_margin", "path_candidates"})
      if (t.values.find(key) == t.values.end())
        f.fail(std::string("task.path_filter is on but the file lacks task.") + key + " (the path filter's data)");
  }
  if (t.obstacles) {
    t.num_obstacles = t.obstacle.num_obstacles;
    if (t.obstacle.num_obstacles < 0 || t.obstacle.num_obstacles > 100000)
      f.fail("task.num_obstacles out of range");
  }
  return t;
}

}  // namespace

std::shared_ptr<const RuntimeController> RuntimeController::load(const std::string& path,
                                                                 const RuntimeLoadOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  ControllerFile file = ControllerFile::read(path);
  const double read = seconds_since(t0);
  auto c = from_file(std::move(file), options);
  const_cast<RuntimeController&>(*c).times_.read_and_check = read;
  return c;
}

std::shared_ptr<const RuntimeController> RuntimeController::from_file(ControllerFile file,
                                                                      const RuntimeLoadOptions& options) {
  std::shared_ptr<RuntimeController> c(new RuntimeController());
  auto t0 = std::chrono::steady_clock::now();
  try {
    c->db_ = database_from_state(database_state(file));
  } catch (const std::invalid_argument& e) {
    file.fail(std::string("inconsistent database sections (") + e.what() + ")");
  }
  const auto valid = file.bytes("db.valid", {c->db_.num_frames});
  if (valid != c->db_.valid) file.fail("section 'db.valid' disagrees with the clip ranges");
  if (c->db_.contacts.empty()) file.fail("the database has no foot contacts");
  c->times_.database = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  c->policy_ = PolicyNet::from_file(file);
  c->task_ = read_task(file, c->policy_.obs_dim(), c->db_);
  if (options.require_path_filter && !(c->task_.obstacles && c->task_.obstacle.path_filter))
    file.fail(c->task_.obstacles
                  ? "the loader requires the collision-aware search, but this obstacles controller has none "
                    "(task.path_filter is off or missing: written before the filter, or trained without it; "
                    "train with --preset mmrl, or --set path_filter=true)"
                  : "the loader requires the collision-aware search, which only obstacles controllers have "
                    "(this file's task core is '" + c->task_.core + "')");
  if (c->policy_.act_dim() != kTrajectoryDim) file.fail("the policy must write 12 trajectory values");
  if (file.has("lmm.header")) c->read_compressed(file);
  const auto ch = numbers(file, "character");
  // The Character only plays: the decisions are the task env's (RuntimeCharacter::decide).
  c->options_.frames_per_step = c->task_.frames_per_step;
  c->options_.inertialization_halflife = static_cast<float>(number(file, ch, "character", "inertialization_halflife"));
  c->options_.ik = number(file, ch, "character", "ik") != 0.0;
  c->options_.foot_locking = number(file, ch, "character", "foot_locking") != 0.0;
  c->times_.policy = seconds_since(t0);
  file.release();
  t0 = std::chrono::steady_clock::now();
  if (std::none_of(c->db_.valid.begin(), c->db_.valid.end(), [](uint8_t v) { return v != 0; }))
    file.fail("the database has no valid frame to match");
  c->matcher_ = std::make_unique<Matcher>(c->db_.normalized.data(), c->db_.num_frames, kFeatureDim,
                                          c->db_.valid.data());
  c->times_.search_tree = seconds_since(t0);
  try {  // the task env's own checks of its config (and of the clip costs), once, at load
    const auto check = [&](auto&& env) {
      if (!c->compressed_) return;
      env.set_compressed(c->compressed_.get(), c->frame_states_.data());
      env.set_action_box(c->action_box_, c->action_box_ + kTrajectoryDim);
    };
    if (c->task_.obstacles)
      check(ObstacleVecEnv(c->db_, *c->matcher_, 1, c->task_.obstacle, 1));
    else
      check(PlaneVecEnv(c->db_, *c->matcher_, 1, c->task_.plane, 1));
    Character(c->db_, *c->matcher_, c->options_);
  } catch (const std::invalid_argument& e) {
    file.fail(std::string("the task's numbers are refused: ") + e.what());
  }
  return c;
}

size_t RuntimeController::memory_bytes() const {
  const Database& d = db_;
  size_t n = 4 * (d.bone_translations.size() + d.bone_rotations.size() + d.root_positions.size() +
                  d.root_yaws.size() + d.root_deltas.size() + d.features.size() + d.normalized.size()) +
             d.valid.size() + d.contacts.size() + 4 * d.frame_clip.size() + 4 * d.clip_ranges.size() +
             4 * d.path_samples.size();
  n += matcher_->tree().memory_bytes();
  n += 4 * policy_.num_parameters();
  if (compressed_) n += compressed_->memory_bytes() + 4 * frame_states_.size();
  return n;
}

// ----------------------------------------------------------------------------- character

RuntimeCharacter::RuntimeCharacter(std::shared_ptr<const RuntimeController> controller, float x, float z,
                                   float yaw, int64_t start_frame)
    : controller_(std::move(controller)),
      character_(controller_->database(), controller_->matcher(), controller_->character_options()) {
  const Database& db = controller_->database();
  if (start_frame < 0) start_frame = std::find(db.valid.begin(), db.valid.end(), 1) - db.valid.begin();
  if (start_frame >= db.num_frames) throw std::invalid_argument("start_frame is outside the database");
  if (!std::isfinite(x) || !std::isfinite(z) || !std::isfinite(yaw))
    throw std::invalid_argument("the start position and yaw must be finite");
  if (!controller_->compressed()) character_.reset(start_frame, RootState{x, z, wrap_angle(yaw)});
  scratch_ = controller_->policy().make_scratch();
  obs_.assign(controller_->policy().obs_dim(), 0.0f);
  action_.assign(kTrajectoryDim, 0.0f);
  target_x_ = x;
  target_z_ = z;
  const RuntimeTask& task = controller_->task();
  k_ = task.frames_per_step;  // the first frame decides
  if (task.obstacles) {
    obstacles_ = std::make_unique<ObstacleVecEnv>(db, controller_->matcher(), 1, task.obstacle, 1);
    const size_t cap = static_cast<size_t>(task.num_obstacles);
    for (auto* v : {&world_centres_, &world_half_sizes_, &world_velocities_, &local_centres_, &local_half_sizes_,
                    &local_velocities_})
      v->assign(cap * 2, 0.0f);
    world_angles_.assign(cap, 0.0f);
    local_angles_.assign(cap, 0.0f);
  } else {
    plane_ = std::make_unique<PlaneVecEnv>(db, controller_->matcher(), 1, task.plane, 1);
  }
  if (const CompressedModel* m = controller_->compressed()) {
    // The start frame's state, decoded: the env holds the state from now on.
    const float* state = with_env([&](auto& env) {
      env.set_compressed(m, controller_->frame_states());
      env.set_action_box(controller_->action_box(), controller_->action_box() + kTrajectoryDim);
      env.set_state(0, start_frame, 0.0f, 0.0f, wrap_angle(yaw));
      return env.compressed_state(0);
    });
    cscratch_ = m->make_scratch();
    row_.assign(static_cast<size_t>(m->pose_dim()), 0.0f);
    m->decode(state, row_.data(), cscratch_);
    character_.reset_row(row_.data(), RootState{x, z, wrap_angle(yaw)});
  }
  pose_.num_joints = controller_->num_joints();
  fill_pose(-1);
}

void RuntimeCharacter::set_request(const std::string& request) {
  if (obstacles_)
    obstacles_->set_request(0, request);
  else
    plane_->set_request(0, request);
}

const std::string& RuntimeCharacter::request() const {
  return obstacles_ ? obstacles_->request(0).request.text : plane_->request(0).request.text;
}

void RuntimeCharacter::set_target(float x, float z) {
  if (!std::isfinite(x) || !std::isfinite(z)) throw std::invalid_argument("target must be finite");
  target_x_ = x;
  target_z_ = z;
  stick_ = false;
}

void RuntimeCharacter::set_stick(float x, float z, float speed) {
  const double length = std::hypot(static_cast<double>(x), static_cast<double>(z));
  if (!std::isfinite(length) || !(length > 0))
    throw std::invalid_argument("stick: the direction (x, z) must be finite and not zero, got (" + std::to_string(x) +
                                ", " + std::to_string(z) + ")");
  if (!std::isfinite(speed) || !(speed > 0))
    throw std::invalid_argument("stick: the speed must be finite and > 0 (m/s), got " + std::to_string(speed));
  stick_x_ = static_cast<float>(x / length);
  stick_z_ = static_cast<float>(z / length);
  stick_speed_ = speed;
  stick_ = true;
}

void RuntimeCharacter::stick_action(float* out) const {
  if (!stick_) throw std::invalid_argument("stick_action: no stick is set (set_stick)");
  // JoystickPolicy.raw_trajectory (arrive off) for the direction d in the character frame.
  const Database& db = controller_->database();
  const Vec2 d = world_to_local_xz(stick_x_, stick_z_, character_.root().yaw);
  float raw[kTrajectoryDim];
  for (int k = 0; k < 3; ++k) {
    const float reach = stick_speed_ * (static_cast<float>(kTrajectoryOffsets[k]) / db.fps);
    raw[4 * k] = d.x() * reach;
    raw[4 * k + 1] = d.y() * reach;
    raw[4 * k + 2] = d.x();
    raw[4 * k + 3] = d.y();
  }
  trajectory_normalize(db, raw, out);
}

void RuntimeCharacter::set_obstacles(int n, const float* centres, const float* half_sizes, const float* angles,
                                     const float* velocities) {
  if (!obstacles_) throw std::invalid_argument("this controller's task has no obstacles");
  const ObstacleTaskConfig& tc = controller_->task().obstacle;
  if (n < 0 || n > tc.num_obstacles)
    throw std::invalid_argument("obstacles: at most " + std::to_string(tc.num_obstacles) + " (the task's num_obstacles)");
  for (int k = 0; k < n; ++k) {
    const float hx = half_sizes[2 * k], hz = half_sizes[2 * k + 1];
    if (!std::isfinite(centres[2 * k]) || !std::isfinite(centres[2 * k + 1]) || !std::isfinite(angles[k]) ||
        !(hx >= 0 && hx <= tc.obstacle_max_side / 2) || !(hz >= 0 && hz <= tc.obstacle_max_side / 2))
      throw std::invalid_argument("obstacles: obstacle " + std::to_string(k) +
                                  " is not finite or has a half size outside [0, obstacle_max_side / 2]");
    if (velocities && !(std::hypot(velocities[2 * k], velocities[2 * k + 1]) <= tc.speed_cap))
      throw std::invalid_argument("obstacles: obstacle " + std::to_string(k) +
                                  "'s velocity is not finite or faster than the task's speed_cap");
  }
  std::copy(centres, centres + 2 * n, world_centres_.begin());
  std::copy(half_sizes, half_sizes + 2 * n, world_half_sizes_.begin());
  std::copy(angles, angles + n, world_angles_.begin());
  if (velocities)
    std::copy(velocities, velocities + 2 * n, world_velocities_.begin());
  else
    std::fill(world_velocities_.begin(), world_velocities_.begin() + 2 * n, 0.0f);
  num_obstacles_ = n;
}

void RuntimeCharacter::sync_env() {
  const RootState& r = character_.root();
  const float tx = target_x_ - r.x, tz = target_z_ - r.z;  // the env's character stands at its origin
  if (plane_) {
    plane_->set_state(0, character_.frame(), 0.0f, 0.0f, r.yaw);  // frame -1 (compressed): the env's state
    plane_->set_target(0, tx, tz);
    return;
  }
  // The obstacles relative to the character: the env's obstacle square is centred on it.
  const float square_half = controller_->task().obstacle.obstacle_square_half;
  int n = 0;
  for (int k = 0; k < num_obstacles_; ++k) {
    const float dx = world_centres_[2 * k] - r.x, dz = world_centres_[2 * k + 1] - r.z;
    if (std::abs(dx) > square_half || std::abs(dz) > square_half) continue;  // beyond every sensor
    local_centres_[2 * n] = dx;
    local_centres_[2 * n + 1] = dz;
    for (int a = 0; a < 2; ++a) {
      local_half_sizes_[2 * n + a] = world_half_sizes_[2 * k + a];
      local_velocities_[2 * n + a] = world_velocities_[2 * k + a];
    }
    local_angles_[n] = world_angles_[k];
    ++n;
  }
  // One new sensor map per decision: observing again before it recomputes the map in place;
  // the first decision's previous map is a copy of its current one, as at a training reset.
  using Maps = ObstacleVecEnv::MapUpdate;
  const Maps maps = decision_.count == 0 ? Maps::kReset : maps_decision_ == decision_.count ? Maps::kReplace : Maps::kPush;
  maps_decision_ = decision_.count;
  obstacles_->set_scene(0, character_.frame(), r.yaw, tx, tz, n, local_centres_.data(), local_half_sizes_.data(),
                        local_angles_.data(), local_velocities_.data(), maps);
}

const float* RuntimeCharacter::observe() {
  sync_env();
  if (plane_)
    plane_->observe(0, obs_.data());
  else
    obstacles_->observe(0, obs_.data());
  return obs_.data();
}

void RuntimeCharacter::decide() {
  const RuntimeController& c = *controller_;
  decision_.root_before = character_.root();
  decision_.frames_before = frames_shown_;
  decision_.target_x = target_x_;
  decision_.target_z = target_z_;
  observe();  // with a stick too: the obstacle tasks' sensor maps keep their history
  if (stick_)
    stick_action(action_.data());
  else
    c.policy().act(obs_.data(), action_.data(), scratch_);
  // The training env's own decision (transition cost, bias_yields, candidate filters); the
  // character plays it.
  const int64_t j = plane_ ? plane_->decide(0, action_.data()) : obstacles_->decide(0, action_.data());
  const float cost = plane_ ? plane_->state(0).last_cost : obstacles_->state(0).last_cost;
  if (controller_->compressed()) {
    with_env([&](auto& env) {
      character_.play_rows(env.compressed_rows(0), env.state(0).last_transition, cost);
      env.end_compressed_playback(0);
    });
  } else {
    character_.play(j, cost);
  }
  decision_.count += 1;
  decision_.match = character_.last_match();
  decision_.transition = character_.last_transition();
  decision_.cost = character_.last_cost();
  decision_.stick = stick_;
  k_ = 0;
}

void RuntimeCharacter::fill_pose(int k) {
  const int J = controller_->num_joints();
  if (k < 0) {  // the reset pose
    pose_.root = character_.root();
    pose_.frame = character_.frame();
    pose_.local_rotations = character_.current_local_rotations();
    pose_.local_translations = character_.current_local_translations();
    pose_.global_positions = character_.current_global_positions();
    pose_.global_rotations = character_.current_global_rotations();
    return;
  }
  const size_t o3 = static_cast<size_t>(k) * J * 3, o4 = static_cast<size_t>(k) * J * 4;
  const float* roots = character_.roots() + 3 * k;
  pose_.root = RootState{roots[0], roots[1], roots[2]};
  pose_.frame = character_.played_frames()[k];
  pose_.local_rotations = character_.local_rotations() + o4;
  pose_.local_translations = character_.local_translations() + o3;
  pose_.global_positions = character_.global_positions() + o3;
  pose_.global_rotations = character_.global_rotations() + o4;
}

const RuntimePose& RuntimeCharacter::advance_frame() {
  if (k_ >= controller_->task().frames_per_step) decide();
  fill_pose(k_);
  k_ += 1;
  frames_shown_ += 1;
  return pose_;
}

const RuntimePose& RuntimeCharacter::update(float dt) {
  // An upper bound: the loop below shows one frame per 1/fps of dt, so a dt of days would hold
  // the caller for hours, and from 2^24 s on `clock_ -= frame_time` no longer changes the float
  // clock (an endless loop).
  if (!(dt >= 0) || !std::isfinite(dt) || dt > kMaxUpdateSeconds)
    throw std::invalid_argument("update: dt must be finite, >= 0 and at most " +
                                std::to_string(static_cast<int>(kMaxUpdateSeconds)) + " s, got " + std::to_string(dt));
  const float frame_time = 1.0f / controller_->fps();
  clock_ += dt;
  // A microsecond of slack: dt = 1 / fps summed in floats shows exactly one frame per call.
  while (clock_ >= frame_time - 1e-6f) {
    clock_ -= frame_time;
    advance_frame();
  }
  if (clock_ < 0) clock_ = 0;
  return pose_;
}

}  // namespace mmrl
