// The engine-facing runtime: load an exported controller (.mmrl, docs/runtime.md) once, then
// drive any number of characters with it. No Python, no torch: Eigen and the core only.
//
//   auto controller = mmrl::RuntimeController::load("controller.mmrl");  // shared, read-only
//   mmrl::RuntimeCharacter hero(controller, x, z, yaw);                  // world meters, radians
//   hero.set_target(tx, tz);                                             // world meters
//   hero.set_stick(dx, dz, speed);                                       // or a stick: world direction, m/s
//   const mmrl::RuntimePose& pose = hero.update(dt);                     // seconds
//
// update(dt) plays the database at its own rate (30 fps): it shows one frame per 1/fps
// seconds of accumulated time, and every frames_per_step frames (6 = 0.2 s) it decides: the
// task's observation (plane: pose features + target in the character frame; obstacles: the
// two sensor maps first), the policy (policy_net.hpp; with a stick set, the stick's
// trajectory in its place), then the match and playback of the full path (character.hpp:
// inertialization, foot locking, two-bone leg IK). These are exactly the decisions of Python's
// full path (mmrl.rollout.FullPath with the same file, start and targets, or with a stick the
// scripted joystick's actions; tests/test_runtime.py compares them).
//
// Spaces: world Y up, X left, Z forward for yaw 0 (forward = (sin yaw, 0, cos yaw)).
// Threads: a RuntimeController is immutable after load and may be shared by characters on
// any threads; a RuntimeCharacter is used by one thread at a time. update() allocates nothing.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "mmrl/character.hpp"
#include "mmrl/policy_net.hpp"
#include "mmrl/runtime_file.hpp"
#include "mmrl/runtime_task.hpp"

namespace mmrl {

// Seconds spent in each part of loading (bench_runtime reports them).
struct RuntimeLoadTimes {
  double read_and_check = 0, database = 0, search_tree = 0, policy = 0;
};

// What an engine requires of the controllers it loads.
struct RuntimeLoadOptions {
  // Refuse a file whose controller has no collision-aware search (an obstacles task with
  // path_filter on, tasks/path_filter.hpp): e.g. a file written before the filter existed.
  bool require_path_filter = false;
};

class RuntimeController {
 public:
  // Loads and checks a controller file. Throws ControllerFileError naming the file and what is
  // wrong (truncated, corrupt, wrong version or byte order, inconsistent sections, or lacking
  // what `options` requires).
  static std::shared_ptr<const RuntimeController> load(const std::string& path,
                                                       const RuntimeLoadOptions& options = {});
  // The same from a parsed file.
  static std::shared_ptr<const RuntimeController> from_file(ControllerFile file,
                                                            const RuntimeLoadOptions& options = {});

  const Database& database() const { return db_; }
  const Matcher& matcher() const { return *matcher_; }
  const PolicyNet& policy() const { return policy_; }
  // The file's task (runtime_task.hpp): its registered core, numbers and observation layout.
  // The decision itself (observation, transition cost, candidate filters, match) is the
  // training task's own: each character holds a one-character task of the core with this config.
  const RuntimeTask& task() const { return task_; }
  const RuntimeTaskType& task_type() const { return *task_type_; }
  const CharacterOptions& character_options() const { return options_; }
  int num_joints() const { return db_.num_joints; }
  float fps() const { return db_.fps; }
  const RuntimeLoadTimes& load_times() const { return times_; }
  // The motion source the characters decide over when it is not the database (a compressed
  // controller's: its database then holds only the start frames; read_motion_source), or null.
  const std::shared_ptr<const MotionSource>& motion_source() const { return source_; }
  // The box of the actions the policy was trained on (low 12, high 12), when the file carries
  // one (a compressed controller's), else null: the database's own box.
  const float* action_box() const { return source_ ? action_box_ : nullptr; }
  // Bytes held: the database's arrays, the search tree, the policy's weights and the motion
  // source's own (MotionSource::memory_bytes).
  size_t memory_bytes() const;

  RuntimeController(const RuntimeController&) = delete;
  RuntimeController& operator=(const RuntimeController&) = delete;

 private:
  RuntimeController() = default;
  Database db_;
  std::shared_ptr<const MotionSource> source_;  // null: the database
  float action_box_[2 * kTrajectoryDim] = {};
  std::unique_ptr<Matcher> matcher_;  // borrows db_.normalized
  PolicyNet policy_;
  RuntimeTask task_;
  const RuntimeTaskType* task_type_ = nullptr;
  CharacterOptions options_;
  RuntimeLoadTimes times_;
};

// A controller file's motion source other than the database (runtime_compressed.cpp: a
// compressed controller's lmm.* sections, docs/runtime.md), or null when it has none; writes the
// box of the actions its policy was trained on into action_box (12 + 12). ControllerFile::fail
// on bad sections.
std::shared_ptr<const MotionSource> read_motion_source(const ControllerFile& file, const Database& db,
                                                       const RuntimeTask& task, float* action_box);

// The pose shown now. Arrays point into the character and stay valid until its next update.
struct RuntimePose {
  RootState root;                     // world (x, z, yaw) of the character frame
  int64_t frame = 0;                  // the database frame shown
  int num_joints = 0;
  const float* local_rotations = nullptr;     // J x 4 (w, x, y, z), BVH locals, root joints in the world
  const float* local_translations = nullptr;  // J x 3, meters
  const float* global_positions = nullptr;    // J x 3, world meters
  const float* global_rotations = nullptr;    // J x 4, world
};

// The last decision (one per frames_per_step frames).
struct RuntimeDecision {
  int64_t count = 0;          // decisions so far
  int64_t frames_before = 0;  // frames shown before it (its time is frames_before / fps)
  RootState root_before;      // the root when it was made
  float target_x = 0, target_z = 0;  // the last target set (a stick's decision does not use it)
  int64_t match = -1;         // the matched frame (played from match + 1)
  bool transition = false;    // not the current clip's continuation
  float cost = 0;             // the match's squared distance (normalized, weighted features)
  bool stick = false;         // made from the stick (set_stick), not by the policy for the target
};

class RuntimeCharacter {
 public:
  // A character on `start_frame` (-1: the first valid frame) at world (x, z) (meters) facing
  // yaw (radians; 0 faces +Z). Its target starts where it stands.
  RuntimeCharacter(std::shared_ptr<const RuntimeController> controller, float x, float z, float yaw,
                   int64_t start_frame = -1);

  // The target, world meters; used from the next decision on. Switches a stick off: the
  // policy decides again.
  void set_target(float x, float z);
  // The facing to arrive with, for a task that reads one (the arrive task: takes_facing()): a
  // world yaw in radians (0 faces +Z), used from the next decision on; such a task refuses to
  // decide until it is set. Throws std::invalid_argument when not finite, or for a task that
  // reads no facing.
  void set_facing(float yaw) { character_task_->set_facing(yaw); }
  bool takes_facing() const { return character_task_->takes_facing(); }
  // A stick in place of the target and the policy, from the next decision on: the player's
  // direction (world x, z; any length > 0, normalized) and speed (m/s, > 0). Each decision's
  // action is then the scripted joystick's (mmrl.rl.policies.JoystickPolicy, arrive off): the
  // trajectory positions d * speed * t at t = 10, 20, 30 frames / fps and the directions d, d
  // the stick's direction in the character frame, normalized with the database's feature
  // mean and scale. Everything after the action is the policy's path: the task's transition
  // cost, clip costs, request, path filter, a compressed controller's decision. set_target
  // switches it off. Throws std::invalid_argument naming a non-finite or zero direction, or a
  // non-finite or non-positive speed; the character is then unchanged.
  void set_stick(float x, float z, float speed);
  bool stick() const { return stick_; }
  // The stick's action for the heading now (12 normalized floats into out), as the next
  // decision takes it; for tools and tests. Throws std::invalid_argument without a stick.
  void stick_action(float* out) const;
  // A request over the database's tags (tags.hpp: "style=elderly & gait=walk"; "" for every
  // clip): from the next decision on, matches keep to the clips carrying it, and a policy
  // conditioned on requests (task.request_groups) observes its code. Throws
  // std::invalid_argument naming an unknown tag (listing those the file has; a file without
  // tags says so) or a request that selects no valid frame; the character is then unchanged.
  void set_request(const std::string& request);
  const std::string& request() const;  // canonical text, "" for every clip
  // Obstacle tasks: the obstacles now, world meters and radians (see grid.hpp: centres and
  // half sizes n x 2, angles n), and optionally their velocities (n x 2, m/s; null: standing
  // still), which the collision-aware search's look-ahead uses. Read at the next decision (the sensor maps); the engine moves them. Throws
  // std::invalid_argument for more obstacles than the task's num_obstacles, a half size over
  // obstacle_max_side / 2 or a speed over speed_cap. Obstacles over the task's square half
  // (10 m) from the character cannot reach its sensors and are ignored.
  void set_obstacles(int n, const float* centres, const float* half_sizes, const float* angles,
                     const float* velocities = nullptr);

  // Advances dt seconds: shows floor(accumulated / frame time) new frames, deciding whenever
  // the last decision's frames are used up. Returns the pose shown now. Throws
  // std::invalid_argument unless 0 <= dt <= kMaxUpdateSeconds (an engine back from a long
  // pause clamps its dt, or resets the character).
  static constexpr float kMaxUpdateSeconds = 60.0f;
  const RuntimePose& update(float dt);
  // Shows exactly one more frame (the unit update() repeats).
  const RuntimePose& advance_frame();

  const RuntimePose& pose() const { return pose_; }
  const RuntimeDecision& last_decision() const { return decision_; }
  int64_t frames_shown() const { return frames_shown_; }
  const Character& character() const { return character_; }
  const RuntimeController& controller() const { return *controller_; }
  // The observation of the next decision (obs_dim floats), for tools and tests.
  const float* observe();

 private:
  void decide();
  void fill_pose(int k);

  std::shared_ptr<const RuntimeController> controller_;
  Character character_;
  PolicyScratch scratch_;
  std::vector<float> obs_, action_;
  float target_x_ = 0, target_z_ = 0;
  bool stick_ = false;
  float stick_x_ = 0, stick_z_ = 0, stick_speed_ = 0;  // unit world direction, m/s
  float clock_ = 0;
  int k_ = 0;  // frames of the last decision shown
  int64_t frames_shown_ = 0;
  RuntimePose pose_;
  RuntimeDecision decision_;
  // The character's one-character task (runtime_task.hpp), whose observe and decide are training's own.
  std::unique_ptr<CharacterTask> character_task_;
  // Tasks with obstacles: the engine's obstacles (world meters), what sync hands the task.
  std::vector<float> centres_, half_sizes_, angles_, velocities_;
  int num_obstacles_ = 0;
};

}  // namespace mmrl
