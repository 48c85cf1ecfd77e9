// Tasks in the engine runtime, by name. A controller file names its task's core (task.core:
// "plane", "obstacles", "arrive"); the runtime looks the core up here, reads the core's config
// from the file's task numbers (its field table: task_config.hpp's visit), checks it by building
// the core's task, and gives each character a CharacterTask: a one-character instance of the
// task (vecenv.hpp's TargetTask: its observation, its rules and the decision engine, without
// training's pool, reseeding or autoreset) behind one interface, so the runtime, the C interface and
// every binding drive any registered task the same way.
//
// Adding a task to the runtime: a file under cpp/runtime/tasks/ with its RuntimeTaskType
// (runtime_task_of<Task>() when the task and its option table are all it needs; a subclass of
// CharacterTaskOf<Task> for the inputs it takes), and one line in runtime_task.cpp's builtin list.
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "mmrl/character.hpp"
#include "mmrl/decider.hpp"
#include "mmrl/decision.hpp"
#include "mmrl/runtime_file.hpp"
#include "mmrl/target_env.hpp"

namespace mmrl {

// A task's numbers as the runtime reads them from a controller file.
struct RuntimeTask {
  std::string name;                     // the task's name ("plane", "obstacles", a plug-in's)
  std::string core;                     // the registered core it runs on
  std::map<std::string, double> values; // every task.keys / task.values pair of the file
  int frames_per_step = 6;
  float success_radius = 0.5f;
  int num_obstacles = 0;                // tasks with obstacles: at most this many (set_obstacles); else 0
  bool path_filter = false;             // the collision-aware search is on (tasks that have it)
  ObsLayout layout;                     // the observation the policy reads, segment by segment
  std::shared_ptr<const EscapeTable> escape_table;  // the file's task.escape_table, or null (built at load)
  std::shared_ptr<const TaskConfig> config;  // the core's own config (its type is the core's)
};

// The world around one character at a decision: its obstacles (world meters, radians, m/s;
// grid.hpp's layout), for tasks that have them.
struct RuntimeObstacles {
  int n = 0;
  const float* centres = nullptr;     // n x 2
  const float* half_sizes = nullptr;  // n x 2
  const float* angles = nullptr;      // n
  const float* velocities = nullptr;  // n x 2
};

// One character's decision context: a one-character task of the task's core. The character
// stands at the task's origin, facing its yaw; everything the engine gives is made relative to it.
class CharacterTask {
 public:
  virtual ~CharacterTask() = default;
  virtual const MotionSource& source() const = 0;
  virtual MotionState& motion() = 0;
  virtual const Decision& decision() const = 0;
  // The motion source (null: the database) and the box of the policy's actions (12 + 12; null:
  // the database's own).
  virtual void set_source(std::shared_ptr<const MotionSource> source, const float* box) = 0;
  // Puts the character on database frame `frame` (-1 keeps a compressed state) facing yaw.
  virtual void start(int64_t frame, float yaw) = 0;
  virtual void set_request(const std::string& request) = 0;
  // Whether the task reads a target facing (the arrive task), set by set_facing (world yaw,
  // radians; std::invalid_argument when not finite, or when the task reads none).
  virtual bool takes_facing() const { return false; }
  virtual void set_facing(float /*yaw*/) {
    throw std::invalid_argument("this controller's task has no target facing");
  }
  virtual const std::string& request() const = 0;
  // Checks obstacles the engine hands in (std::invalid_argument naming what is wrong); a task
  // without obstacles refuses any.
  virtual void check_obstacles(const RuntimeObstacles& obstacles) const = 0;
  // Feeds the decision's inputs: the character's root (world), its target (world meters) and
  // obstacles; `decision` counts the character's decisions (0: its first; the same count
  // again: observing again before the same decision).
  virtual void sync(const RootState& root, int64_t frame, float target_x, float target_z,
                    const RuntimeObstacles& obstacles, int64_t decision) = 0;
  virtual void observe(float* obs) = 0;
  virtual void decide(const float* action) = 0;
  virtual void end_playback() = 0;
  virtual ObsLayout layout() const = 0;
};

// A registered task core.
struct RuntimeTaskType {
  std::string core;
  bool searches_paths = false;  // the core has the collision-aware search (task.path_filter)
  // Reads the core's config from the file's task numbers and optional sections into t.config,
  // and what the runtime reports of it (t.num_obstacles, t.path_filter); ControllerFile::fail
  // on bad numbers. The shared fields (frames_per_step, success_radius, layout) are filled by
  // the loader.
  void (*read_config)(const ControllerFile& file, RuntimeTask& t, const Database& db);
  // A one-character task of this core over db (borrowed) with t's config; throws
  // std::invalid_argument when the task refuses the config.
  std::unique_ptr<CharacterTask> (*make_task)(const Database& db, const Matcher& matcher, const RuntimeTask& t);
};

// The registered cores (plane, obstacles, arrive), in registration order; null for an unknown name.
const std::vector<RuntimeTaskType>& runtime_task_types();
const RuntimeTaskType* find_runtime_task(const std::string& core);

// A number as a file's reader writes it (0, 1, 2.5).
inline std::string format_number(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

// The config of a task core from the file's task numbers (by Config::visit's field names; a
// field the file lacks keeps its default) and its optional per-clip and text sections.
// A retired option (Config::retired) with another value than the code now runs is refused: the
// file was written for a rule this runtime no longer has.
template <class Config>
Config runtime_task_config(const ControllerFile& f, const RuntimeTask& t, int64_t num_clips) {
  for (const RetiredOption& r : Config::retired()) {
    const auto it = t.values.find(r.name);
    if (r.deployed && it != t.values.end() && it->second != r.now)
      f.fail(std::string("task.") + r.name + " is " + format_number(it->second) + ": an experiment's option " +
             "this runtime no longer has (it always runs " + format_number(r.now) + "; docs/obstacles.md, " +
             "\"Retired options\")");
  }
  Config c;
  Config::visit([&](const char* name, auto member, const OptionRange&, const char*) {
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

// A core whose runtime needs nothing but its task and its option table: its registration
// (Task: a TargetTask with kCoreName and a Config with visit).
template <class Task>
RuntimeTaskType runtime_task_of();

// What every core's CharacterTask does with its task (a TargetTask of one character); a core
// adds its scene (sync, check_obstacles) in a subclass.
template <class Task>
class CharacterTaskOf : public CharacterTask {
 public:
  using Config = typename Task::ConfigType;
  CharacterTaskOf(const Database& db, const Matcher& matcher, const RuntimeTask& t)
      : task_(db, matcher, 1, static_cast<const Config&>(*t.config)) {}
  const MotionSource& source() const override { return task_.source(); }
  MotionState& motion() override { return task_.state(0); }
  const Decision& decision() const override { return task_.state(0).decision; }
  void set_source(std::shared_ptr<const MotionSource> source, const float* box) override {
    task_.set_source(std::move(source));
    if (box != nullptr) task_.set_action_box(box, box + kTrajectoryDim);
  }
  void start(int64_t frame, float yaw) override { task_.set_state(0, frame, 0.0f, 0.0f, wrap_angle(yaw)); }
  void set_request(const std::string& request) override { task_.set_request(0, request); }
  const std::string& request() const override { return task_.request(0).request.text; }
  void check_obstacles(const RuntimeObstacles&) const override {
    throw std::invalid_argument("this controller's task has no obstacles");
  }
  void sync(const RootState& root, int64_t frame, float target_x, float target_z, const RuntimeObstacles&,
            int64_t) override {
    task_.set_state(0, frame, 0.0f, 0.0f, root.yaw);  // frame -1 (compressed): the task keeps its state
    task_.set_target(0, target_x - root.x, target_z - root.z);
  }
  void observe(float* obs) override { task_.observe(0, obs); }
  void decide(const float* action) override { task_.decide(0, action); }
  void end_playback() override { task_.end_playback(0); }
  ObsLayout layout() const override { return task_.obs_layout(); }

 protected:
  Task task_;  // the character's task
};

template <class Task>
RuntimeTaskType runtime_task_of() {
  using Config = typename Task::ConfigType;
  RuntimeTaskType t;
  t.core = Task::kCoreName;
  t.read_config = [](const ControllerFile& f, RuntimeTask& task, const Database& db) {
    task.config = std::make_shared<Config>(runtime_task_config<Config>(f, task, db.num_clips()));
  };
  t.make_task = [](const Database& db, const Matcher& matcher, const RuntimeTask& task) -> std::unique_ptr<CharacterTask> {
    return std::make_unique<CharacterTaskOf<Task>>(db, matcher, task);
  };
  return t;
}

}  // namespace mmrl
