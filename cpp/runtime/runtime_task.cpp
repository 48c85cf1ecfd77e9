#include "mmrl/runtime_task.hpp"

namespace mmrl {

// Each built-in core's registration (cpp/runtime/tasks/<name>.cpp), from the one list.
#define MMRL_TASK(name) RuntimeTaskType name##_runtime_task();
#include "mmrl/tasks/builtin.hpp"
#undef MMRL_TASK

const std::vector<RuntimeTaskType>& runtime_task_types() {
  static const std::vector<RuntimeTaskType> types = {
#define MMRL_TASK(name) name##_runtime_task(),
#include "mmrl/tasks/builtin.hpp"
#undef MMRL_TASK
  };
  return types;
}

const RuntimeTaskType* find_runtime_task(const std::string& core) {
  for (const RuntimeTaskType& t : runtime_task_types())
    if (t.core == core) return &t;
  return nullptr;
}

}  // namespace mmrl
