// The built-in task cores, one line each. MMRL_TASK(name) registers the core `name` with both C++
// registries: the Python bindings (bind_<name>, cpp/bindings/bind_<name>.cpp) and the engine
// runtime (<name>_runtime_task, cpp/runtime/tasks/<name>.cpp). A new core is one line here.
// No include guard: each registry includes the list with its own MMRL_TASK.
MMRL_TASK(plane)
MMRL_TASK(obstacles)
MMRL_TASK(arrive)
