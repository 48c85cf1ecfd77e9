// The moving-obstacles task in the engine runtime (runtime_task.hpp): the engine's obstacles,
// made relative to the character (the task's obstacle square is centred on it), feed the task's
// own sensor maps, rules and decision.
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "mmrl/runtime_task.hpp"
#include "mmrl/tasks/obstacles.hpp"

namespace mmrl {

namespace {

class ObstaclesCharacterTask final : public CharacterTaskOf<ObstacleTask> {
 public:
  ObstaclesCharacterTask(const Database& db, const Matcher& matcher, const RuntimeTask& t)
      : CharacterTaskOf(db, matcher, t) {
    const size_t cap = static_cast<size_t>(task_.config().num_obstacles);
    for (auto* v : {&centres_, &half_sizes_, &velocities_}) v->assign(cap * 2, 0.0f);
    angles_.assign(cap, 0.0f);
  }

  void check_obstacles(const RuntimeObstacles& o) const override {
    const ObstacleTaskConfig& tc = task_.config();
    if (o.n < 0 || o.n > tc.num_obstacles)
      throw std::invalid_argument("obstacles: at most " + std::to_string(tc.num_obstacles) + " (the task's num_obstacles)");
    for (int k = 0; k < o.n; ++k) {
      const float hx = o.half_sizes[2 * k], hz = o.half_sizes[2 * k + 1];
      if (!std::isfinite(o.centres[2 * k]) || !std::isfinite(o.centres[2 * k + 1]) || !std::isfinite(o.angles[k]) ||
          !(hx >= 0 && hx <= tc.obstacle_max_side / 2) || !(hz >= 0 && hz <= tc.obstacle_max_side / 2))
        throw std::invalid_argument("obstacles: obstacle " + std::to_string(k) +
                                    " is not finite or has a half size outside [0, obstacle_max_side / 2]");
      if (o.velocities && !(std::hypot(o.velocities[2 * k], o.velocities[2 * k + 1]) <= tc.speed_cap))
        throw std::invalid_argument("obstacles: obstacle " + std::to_string(k) +
                                    "'s velocity is not finite or faster than the task's speed_cap");
    }
  }

  void sync(const RootState& r, int64_t frame, float target_x, float target_z, const RuntimeObstacles& o,
            int64_t decision) override {
    const float square_half = task_.config().obstacle_square_half;
    int n = 0;
    for (int k = 0; k < o.n; ++k) {
      const float dx = o.centres[2 * k] - r.x, dz = o.centres[2 * k + 1] - r.z;
      if (std::abs(dx) > square_half || std::abs(dz) > square_half) continue;  // beyond every sensor
      centres_[2 * n] = dx;
      centres_[2 * n + 1] = dz;
      for (int a = 0; a < 2; ++a) {
        half_sizes_[2 * n + a] = o.half_sizes[2 * k + a];
        velocities_[2 * n + a] = o.velocities ? o.velocities[2 * k + a] : 0.0f;
      }
      angles_[n] = o.angles[k];
      ++n;
    }
    // One new sensor map per decision: observing again before it recomputes the map in place;
    // the first decision's previous map is a copy of its current one, as at a training reset.
    using Maps = ObstacleTask::MapUpdate;
    const Maps maps = decision == 0 ? Maps::kReset : maps_decision_ == decision ? Maps::kReplace : Maps::kPush;
    maps_decision_ = decision;
    task_.set_scene(0, frame, r.yaw, target_x - r.x, target_z - r.z, n, centres_.data(), half_sizes_.data(),
                   angles_.data(), velocities_.data(), maps);
  }

 private:
  // The obstacles relative to the character (the task's square is centred on it).
  std::vector<float> centres_, half_sizes_, angles_, velocities_;
  int64_t maps_decision_ = -1;  // the decision the newest sensor map was made for
};

}  // namespace

RuntimeTaskType obstacles_runtime_task() {
  RuntimeTaskType t;
  t.core = ObstacleTask::kCoreName;
  t.searches_paths = true;
  t.read_config = [](const ControllerFile& f, RuntimeTask& task, const Database& db) {
    auto config = std::make_shared<ObstacleTaskConfig>(runtime_task_config<ObstacleTaskConfig>(f, task, db.num_clips()));
    if (config->path_filter) {  // the collision-aware search needs its numbers
      for (const char* key : {"path_cost", "path_horizon", "path_margin", "path_candidates"})
        if (task.values.find(key) == task.values.end())
          f.fail(std::string("task.path_filter is on but the file lacks task.") + key + " (the path filter's data)");
    }
    // The escapes' nearest frames, found at export (optional: without it the table is built when
    // the controller loads, seconds for a large database).
    if (f.has("task.escape_table")) {
      const int escapes = config->path_filter ? config->path_escapes : 0, k = config->path_fan_candidates;
      if (escapes == 0) f.fail("section 'task.escape_table' is present but the file's search takes no escapes");
      try {
        task.escape_table = std::make_shared<const EscapeTable>(
            db.num_frames, escapes, k, f.ints("task.escape_table", {db.num_frames, int64_t(escapes) * k}));
      } catch (const std::invalid_argument& e) {
        f.fail(std::string("section 'task.escape_table': ") + e.what());
      }
    }
    task.num_obstacles = config->num_obstacles;
    task.path_filter = config->path_filter;
    task.config = std::move(config);
  };
  t.make_task = [](const Database& db, const Matcher& matcher, const RuntimeTask& task) -> std::unique_ptr<CharacterTask> {
    if (task.escape_table) {  // the task finds the file's table where it would keep the one it builds
      const auto& c = static_cast<const ObstacleTaskConfig&>(*task.config);
      EscapeTable::shared(db, matcher, c.path_escapes, c.path_fan_candidates, task.escape_table);
    }
    return std::make_unique<ObstaclesCharacterTask>(db, matcher, task);
  };
  return t;
}

}  // namespace mmrl
