// The plane task in the engine runtime (runtime_task.hpp): the task's own observation and
// decision; the character's target, relative to it, is all it needs.
#include "mmrl/runtime_task.hpp"
#include "mmrl/tasks/plane.hpp"

namespace mmrl {

RuntimeTaskType plane_runtime_task() { return runtime_task_of<PlaneTask>(); }

}  // namespace mmrl
