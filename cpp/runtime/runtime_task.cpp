#include "mmrl/runtime_task.hpp"

namespace mmrl {

// Each built-in core's registration (cpp/runtime/tasks/).
RuntimeTaskType plane_runtime_task();
RuntimeTaskType obstacles_runtime_task();
RuntimeTaskType arrive_runtime_task();

const std::vector<RuntimeTaskType>& runtime_task_types() {
  static const std::vector<RuntimeTaskType> types = {
      plane_runtime_task(),
      obstacles_runtime_task(),
      arrive_runtime_task(),
  };
  return types;
}

const RuntimeTaskType* find_runtime_task(const std::string& core) {
  for (const RuntimeTaskType& t : runtime_task_types())
    if (t.core == core) return &t;
  return nullptr;
}

}  // namespace mmrl
