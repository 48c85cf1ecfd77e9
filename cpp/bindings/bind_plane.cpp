// Bindings of the plane task (tasks/plane.hpp): its config and env from the shared task
// bindings (bind_task_env.hpp), and its step. No logic.
#include "bind_task_env.hpp"
#include "bindings.hpp"
#include "mmrl/tasks/plane.hpp"

namespace mmrl {

namespace {

// The env borrows the database and the matcher; keep_alive holds their Python owners.
struct PyPlaneVecEnv {
  PlaneVecEnv env;
};

}  // namespace

void bind_plane(py::module_& m) {
  auto config = bind_task_config<PlaneTaskConfig>(m, "PlaneTaskConfig", "Numbers of the plane task (see tasks/plane.hpp).");
  m.attr("TargetTaskConfig") = config;  // the old name, deprecated: kept for one release

  py::class_<PyPlaneVecEnv> plane(m, "PlaneVecEnv", "Batched plane-task environments (C++ core of mmrl.tasks.plane).");
  bind_task_env(
      plane, [](const PlaneVecEnv& env, int i) { return target_state_dict(env.state(i)); },
      "Writes into out (int32, N) how many frames of the last step each environment played before its episode ended: "
      "the index of the first frame within success_radius + 1, else frames_per_step (0 after reset).");
  bind_shared_step(plane);
}

}  // namespace mmrl
