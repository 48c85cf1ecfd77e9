#include "mmrl/runtime.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "mmrl/database_io.hpp"
#include "mmrl/tags.hpp"
#include "mmrl/tasks/obstacles.hpp"  // the legacy core rule of read_task
#include "mmrl/tasks/plane.hpp"

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

RuntimeTask read_task(const ControllerFile& f, int obs_dim, const Database& db) {
  RuntimeTask t;
  const auto names = f.texts("task.name");
  if (names.size() != 1) f.fail("section 'task.name' must hold one name");
  t.name = names[0];
  t.values = numbers(f, "task");
  for (const char* key : {"frames_per_step", "action_limit_std", "transition_cost", "success_radius"})
    number(f, t.values, "task", key);  // required
  // The core the task runs on: named by the file (task.core), else (files written before
  // task.core) the task's own name when it is a core's, else the core whose observation has
  // the policy's size (those files had the plane and obstacles cores only).
  if (f.has("task.core")) {
    const auto core = f.texts("task.core");
    if (core.size() != 1) f.fail("section 'task.core' must hold one name");
    t.core = core[0];
  } else if (find_runtime_task(t.name) != nullptr) {
    t.core = t.name;
  } else {
    t.core = obs_dim == ObstacleTask::kObsDim ? ObstacleTask::kCoreName : PlaneTask::kCoreName;
  }
  const RuntimeTaskType* type = find_runtime_task(t.core);
  if (type == nullptr) {
    std::string cores;
    for (const RuntimeTaskType& k : runtime_task_types()) cores += (cores.empty() ? "" : ", ") + k.core;
    f.fail("task.core '" + t.core + "' is not a core this runtime has (" + cores + ")");
  }
  type->read_config(f, t, db);
  try {
    RequestCode(db, t.config->request_groups);
  } catch (const std::invalid_argument& e) {
    f.fail(std::string("task.request_groups: ") + e.what());
  }
  t.frames_per_step = t.config->frames_per_step;
  t.success_radius = t.config->success_radius;
  return t;
}

// "pose 15, goal 2, request 7": a layout in words.
std::string layout_text(const ObsLayout& layout) {
  std::string out;
  for (const ObsSegment& s : layout)
    out += (out.empty() ? "" : ", ") + s.name + " " + std::to_string(s.size) + (s.option.empty() ? "" : " (" + s.option + ")");
  return out;
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
  c->task_type_ = find_runtime_task(c->task_.core);
  if (options.require_path_filter && !(c->task_type_->searches_paths && c->task_.path_filter))
    file.fail(c->task_type_->searches_paths
                  ? "the loader requires the collision-aware search, but this " + c->task_.core +
                        " controller has none "
                    "(task.path_filter is off or missing: written before the filter, or trained without it; "
                    "train with --preset mmrl, or --set path_filter=true)"
                  : "the loader requires the collision-aware search, which this file's task core ('" +
                        c->task_.core + "') does not have");
  if (c->policy_.act_dim() != kTrajectoryDim) file.fail("the policy must write 12 trajectory values");
  c->source_ = read_motion_source(file, c->db_, c->task_, c->action_box_);
  const auto ch = numbers(file, "character");
  // The Character only plays: the decisions are the character's task's (RuntimeCharacter::decide).
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
  try {  // the task's own checks of its config (and of the clip costs), once, at load
    const std::unique_ptr<CharacterTask> character_task = c->task_type_->make_task(c->db_, *c->matcher_, c->task_);
    character_task->set_source(c->source_, c->action_box());
    c->task_.layout = character_task->layout();
    Character(c->db_, c->options_);
  } catch (const std::invalid_argument& e) {
    file.fail(std::string("the task's numbers are refused: ") + e.what());
  }
  int want = 0;
  for (const ObsSegment& s : c->task_.layout) want += s.size;
  if (c->policy_.obs_dim() != want)
    file.fail("the policy reads " + std::to_string(c->policy_.obs_dim()) + " observations; the " + c->task_.core +
              " task's are " + std::to_string(want) + " (" + layout_text(c->task_.layout) + ")");
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
  if (source_) n += source_->memory_bytes();
  return n;
}

// ----------------------------------------------------------------------------- character

RuntimeCharacter::RuntimeCharacter(std::shared_ptr<const RuntimeController> controller, float x, float z,
                                   float yaw, int64_t start_frame)
    : controller_(std::move(controller)),
      character_(controller_->database(), controller_->character_options()) {
  const Database& db = controller_->database();
  if (start_frame < 0) start_frame = std::find(db.valid.begin(), db.valid.end(), 1) - db.valid.begin();
  if (start_frame >= db.num_frames) throw std::invalid_argument("start_frame is outside the database");
  if (!std::isfinite(x) || !std::isfinite(z) || !std::isfinite(yaw))
    throw std::invalid_argument("the start position and yaw must be finite");
  scratch_ = controller_->policy().make_scratch();
  obs_.assign(controller_->policy().obs_dim(), 0.0f);
  action_.assign(kTrajectoryDim, 0.0f);
  target_x_ = x;
  target_z_ = z;
  const RuntimeTask& task = controller_->task();
  k_ = task.frames_per_step;  // the first frame decides
  character_task_ = controller_->task_type().make_task(db, controller_->matcher(), task);
  const size_t cap = static_cast<size_t>(task.num_obstacles);
  for (auto* v : {&centres_, &half_sizes_, &velocities_}) v->assign(cap * 2, 0.0f);
  angles_.assign(cap, 0.0f);
  // The task's motion source holds the character's place in its motion from now on (a
  // compressed controller's state, or the frame the character shows); the character shows it.
  character_task_->set_source(controller_->motion_source(), controller_->action_box());
  character_task_->start(start_frame, yaw);
  character_task_->source().show(character_, character_task_->motion(), RootState{x, z, wrap_angle(yaw)});
  pose_.num_joints = controller_->num_joints();
  fill_pose(-1);
}

void RuntimeCharacter::set_request(const std::string& request) { character_task_->set_request(request); }

const std::string& RuntimeCharacter::request() const { return character_task_->request(); }

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
  character_task_->check_obstacles(RuntimeObstacles{n, centres, half_sizes, angles, velocities});
  std::copy(centres, centres + 2 * n, centres_.begin());
  std::copy(half_sizes, half_sizes + 2 * n, half_sizes_.begin());
  std::copy(angles, angles + n, angles_.begin());
  if (velocities)
    std::copy(velocities, velocities + 2 * n, velocities_.begin());
  else
    std::fill(velocities_.begin(), velocities_.begin() + 2 * n, 0.0f);
  num_obstacles_ = n;
}

const float* RuntimeCharacter::observe() {
  character_task_->sync(character_.root(), character_.frame(), target_x_, target_z_,
             RuntimeObstacles{num_obstacles_, centres_.data(), half_sizes_.data(), angles_.data(), velocities_.data()},
             decision_.count);
  character_task_->observe(obs_.data());
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
  // The training task's own decision (transition cost, candidate filters); its
  // motion source plays it on the character.
  character_task_->decide(action_.data());
  character_task_->source().play(character_, character_task_->motion(), character_task_->decision());
  character_task_->end_playback();
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
