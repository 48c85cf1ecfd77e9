#include "mmrl/runtime.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "mmrl/database_io.hpp"

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
    if (!std::isfinite(values[k])) f.fail("'" + prefix + "." + keys[k] + "' is not finite");
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

RuntimeTask read_task(const ControllerFile& f, int obs_dim) {
  RuntimeTask t;
  const auto names = f.texts("task.name");
  if (names.size() != 1) f.fail("section 'task.name' must hold one name");
  t.name = names[0];
  t.values = numbers(f, "task");
  auto get = [&](const char* key) { return number(f, t.values, "task", key); };
  t.frames_per_step = static_cast<int>(get("frames_per_step"));
  t.action_limit_std = static_cast<float>(get("action_limit_std"));
  t.transition_cost = static_cast<float>(get("transition_cost"));
  t.success_radius = static_cast<float>(get("success_radius"));
  if (t.frames_per_step < 1 || t.frames_per_step > 30) f.fail("task.frames_per_step must be in 1..30");
  t.obstacles = obs_dim == 2 * kMapCells + kPoseDim + 2;
  if (!t.obstacles && obs_dim != kPoseDim + 2)
    f.fail("the policy reads " + std::to_string(obs_dim) + " observations: neither the plane task's (17) nor an "
           "obstacle task's (529)");
  if (t.obstacles) {
    t.previous_map_lag = static_cast<int>(get("previous_map_lag"));
    t.bias_yields = get("bias_yields") != 0.0;
    t.hit_radius = static_cast<float>(get("hit_radius"));
    t.field.num_obstacles = static_cast<int>(get("num_obstacles"));
    t.field.square_half = static_cast<float>(get("obstacle_square_half"));
    t.field.min_side = static_cast<float>(get("obstacle_min_side"));
    t.field.max_side = static_cast<float>(get("obstacle_max_side"));
    t.field.cell_size = static_cast<float>(get("grid_cell_size"));
    t.field.sensor_size = static_cast<float>(get("sensor_size"));
    t.field.sensor_forward = static_cast<float>(get("sensor_forward"));
    t.field.max_margin = std::max(1.0f, t.hit_radius);
    if (t.previous_map_lag < 1 || t.previous_map_lag > 64 || t.field.num_obstacles < 0 ||
        t.field.num_obstacles > 100000)
      f.fail("task.previous_map_lag or task.num_obstacles out of range");
  }
  return t;
}

}  // namespace

std::shared_ptr<const RuntimeController> RuntimeController::load(const std::string& path) {
  const auto t0 = std::chrono::steady_clock::now();
  ControllerFile file = ControllerFile::read(path);
  const double read = seconds_since(t0);
  auto c = from_file(std::move(file));
  const_cast<RuntimeController&>(*c).times_.read_and_check = read;
  return c;
}

std::shared_ptr<const RuntimeController> RuntimeController::from_file(ControllerFile file) {
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
  c->task_ = read_task(file, c->policy_.obs_dim());
  if (c->policy_.act_dim() != kTrajectoryDim) file.fail("the policy must write 12 trajectory values");
  const auto ch = numbers(file, "character");
  c->options_.frames_per_step = c->task_.frames_per_step;
  c->options_.action_limit_std = c->task_.action_limit_std;
  c->options_.transition_cost = c->task_.transition_cost;
  c->options_.inertialization_halflife = static_cast<float>(number(file, ch, "character", "inertialization_halflife"));
  c->options_.ik = number(file, ch, "character", "ik") != 0.0;
  c->options_.foot_locking = number(file, ch, "character", "foot_locking") != 0.0;
  if (!(c->options_.transition_cost >= 0)) file.fail("task.transition_cost must be >= 0");
  if (file.has("task.clip_costs")) {  // the decision's clip-cost filter (controller.hpp), optional
    c->options_.clip_costs = file.floats("task.clip_costs", {c->db_.num_clips()});
    try {
      ClipCostFilter check(c->db_, c->options_.clip_costs, "task.clip_costs");
    } catch (const std::invalid_argument& e) {
      file.fail(e.what());
    }
  }
  c->times_.policy = seconds_since(t0);
  file.release();
  t0 = std::chrono::steady_clock::now();
  if (std::none_of(c->db_.valid.begin(), c->db_.valid.end(), [](uint8_t v) { return v != 0; }))
    file.fail("the database has no valid frame to match");
  c->matcher_ = std::make_unique<Matcher>(c->db_.normalized.data(), c->db_.num_frames, kFeatureDim,
                                          c->db_.valid.data());
  c->times_.search_tree = seconds_since(t0);
  return c;
}

size_t RuntimeController::memory_bytes() const {
  const Database& d = db_;
  size_t n = 4 * (d.bone_translations.size() + d.bone_rotations.size() + d.root_positions.size() +
                  d.root_yaws.size() + d.root_deltas.size() + d.features.size() + d.normalized.size()) +
             d.valid.size() + d.contacts.size() + 4 * d.frame_clip.size() + 4 * d.clip_ranges.size();
  n += matcher_->tree().memory_bytes();
  n += 4 * policy_.num_parameters();
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
  character_.reset(start_frame, RootState{x, z, wrap_angle(yaw)});
  scratch_ = controller_->policy().make_scratch();
  obs_.assign(controller_->policy().obs_dim(), 0.0f);
  action_.assign(kTrajectoryDim, 0.0f);
  target_x_ = x;
  target_z_ = z;
  k_ = controller_->task().frames_per_step;  // the first frame decides
  const RuntimeTask& task = controller_->task();
  if (task.obstacles) {
    ObstacleFieldConfig fc = task.field;
    field_ = std::make_unique<ObstacleField>(1, fc);
    const size_t cap = static_cast<size_t>(fc.num_obstacles);
    obstacle_centres_.assign(cap * 2, 0);
    obstacle_half_sizes_.assign(cap * 2, 0);
    obstacle_angles_.assign(cap, 0);
    zero_velocities_.assign(cap * 2, 0);
    local_centres_.assign(cap * 2, 0);
    local_half_sizes_.assign(cap * 2, 0);
    local_angles_.assign(cap, 0);
    maps_.assign(static_cast<size_t>(task.previous_map_lag + 1) * kMapCells, 0);
  }
  pose_.num_joints = controller_->num_joints();
  fill_pose(-1);
}

void RuntimeCharacter::set_target(float x, float z) {
  if (!std::isfinite(x) || !std::isfinite(z)) throw std::invalid_argument("target must be finite");
  target_x_ = x;
  target_z_ = z;
}

void RuntimeCharacter::set_obstacles(int n, const float* centres, const float* half_sizes, const float* angles) {
  if (!field_) throw std::invalid_argument("this controller's task has no obstacles");
  const ObstacleFieldConfig& fc = controller_->task().field;
  if (n < 0 || n > fc.num_obstacles)
    throw std::invalid_argument("obstacles: at most " + std::to_string(fc.num_obstacles) + " (the task's num_obstacles)");
  for (int k = 0; k < n; ++k) {
    const float hx = half_sizes[2 * k], hz = half_sizes[2 * k + 1];
    if (!std::isfinite(centres[2 * k]) || !std::isfinite(centres[2 * k + 1]) || !std::isfinite(angles[k]) ||
        !(hx >= 0 && hx <= fc.max_side / 2) || !(hz >= 0 && hz <= fc.max_side / 2))
      throw std::invalid_argument("obstacles: obstacle " + std::to_string(k) +
                                  " is not finite or has a half size outside [0, obstacle_max_side / 2]");
  }
  std::copy(centres, centres + 2 * n, obstacle_centres_.begin());
  std::copy(half_sizes, half_sizes + 2 * n, obstacle_half_sizes_.begin());
  std::copy(angles, angles + n, obstacle_angles_.begin());
  num_obstacles_ = n;
}

}  // namespace mmrl

namespace mmrl {

void RuntimeCharacter::refresh_maps(bool keep_previous) {
  // The obstacles relative to the character: the field's square is centred on it.
  const RootState& r = character_.root();
  const ObstacleFieldConfig& fc = controller_->task().field;
  int n = 0;
  for (int k = 0; k < num_obstacles_; ++k) {
    const float dx = obstacle_centres_[2 * k] - r.x, dz = obstacle_centres_[2 * k + 1] - r.z;
    if (std::abs(dx) > fc.square_half || std::abs(dz) > fc.square_half) continue;  // beyond every sensor
    local_centres_[2 * n] = dx;
    local_centres_[2 * n + 1] = dz;
    local_half_sizes_[2 * n] = obstacle_half_sizes_[2 * k];
    local_half_sizes_[2 * n + 1] = obstacle_half_sizes_[2 * k + 1];
    local_angles_[n] = obstacle_angles_[k];
    ++n;
  }
  field_->set(0, n, local_centres_.data(), local_half_sizes_.data(), local_angles_.data(), zero_velocities_.data());
  field_->rebuild(0, controller_->task().hit_radius);
  const int slots = controller_->task().previous_map_lag + 1;
  // One new map per decision: observing again before the decision recomputes it in place.
  const bool new_map = keep_previous && maps_decision_ != decision_.count;
  if (new_map) map_head_ = (map_head_ + 1) % slots;
  maps_decision_ = decision_.count;
  uint8_t* cur = &maps_[static_cast<size_t>(map_head_) * kMapCells];
  field_->sensor_map(0, 0.0f, 0.0f, r.yaw, cur);
  if (!keep_previous)
    for (int k = 0; k < slots; ++k)
      if (k != map_head_) std::copy(cur, cur + kMapCells, &maps_[static_cast<size_t>(k) * kMapCells]);
}

const float* RuntimeCharacter::observe() {
  const Database& db = controller_->database();
  const RootState& r = character_.root();
  float* o = obs_.data();
  if (field_) {
    refresh_maps(decision_.count > 0);
    const int slots = controller_->task().previous_map_lag + 1;
    const uint8_t* cur = &maps_[static_cast<size_t>(map_head_) * kMapCells];
    const uint8_t* prev = &maps_[static_cast<size_t>((map_head_ + 1) % slots) * kMapCells];
    for (int k = 0; k < kMapCells; ++k) o[k] = cur[k];
    for (int k = 0; k < kMapCells; ++k) o[kMapCells + k] = prev[k];
    o += 2 * kMapCells;
  }
  // c_t and g_t exactly as the task envs write them (vecenv.hpp: observe_pose, observe_goal).
  const float* pose = &db.normalized[static_cast<size_t>(character_.frame()) * kFeatureDim];
  std::copy(pose, pose + kPoseDim, o);
  const Vec2 g = world_to_local_xz(target_x_ - r.x, target_z_ - r.z, r.yaw);
  o[kPoseDim] = g.x();
  o[kPoseDim + 1] = g.y();
  return obs_.data();
}

void RuntimeCharacter::decide() {
  const RuntimeController& c = *controller_;
  decision_.root_before = character_.root();
  decision_.frames_before = frames_shown_;
  decision_.target_x = target_x_;
  decision_.target_z = target_z_;
  observe();
  c.policy().act(obs_.data(), action_.data(), scratch_);
  if (field_ && c.task().bias_yields && c.task().transition_cost > 0) {
    // The obstacles task's bias_yields: no continuation bias when the current frame's own
    // future trajectory runs into an obstacle (tested where the obstacles are now).
    const float* cont = &c.database().features[static_cast<size_t>(character_.frame()) * kFeatureDim + kPoseDim];
    bool hit = false;
    for (int k = 0; k < 3 && !hit; ++k) {
      const Vec2 p = local_to_world_xz(cont[4 * k], cont[4 * k + 1], character_.root().yaw);  // the field is centred on the root
      hit = field_->disc_overlaps_any(0, p.x(), p.y(), c.task().hit_radius);
    }
    character_.set_transition_cost(hit ? 0.0f : c.task().transition_cost);
  }
  character_.step(action_.data());
  decision_.count += 1;
  decision_.match = character_.last_match();
  decision_.transition = character_.last_transition();
  decision_.cost = character_.last_cost();
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
