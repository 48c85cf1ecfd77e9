// The plane task in the engine runtime (runtime_task.hpp): the env's own observation and
// decision; the character's target, relative to it, is all it needs.
#include "mmrl/runtime_task.hpp"
#include "mmrl/tasks/plane.hpp"

namespace mmrl {

RuntimeTaskType plane_runtime_task() {
  RuntimeTaskType t;
  t.core = PlaneVecEnv::kCoreName;
  t.read_config = [](const ControllerFile& f, RuntimeTask& task, const Database& db) {
    task.config = std::make_shared<PlaneTaskConfig>(runtime_task_config<PlaneTaskConfig>(f, task, db.num_clips()));
  };
  t.make_env = [](const Database& db, const Matcher& matcher, const RuntimeTask& task) -> std::unique_ptr<RuntimeTaskEnv> {
    return std::make_unique<RuntimeTaskEnvOf<PlaneVecEnv>>(db, matcher, task);
  };
  return t;
}

}  // namespace mmrl
