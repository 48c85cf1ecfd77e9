// Bindings of the arrive task (tasks/arrive.hpp): its config and env from the shared task
// bindings (bind_task_env.hpp), its step and its facing. No logic.
#include "bind_task_env.hpp"
#include "mmrl/tasks/arrive.hpp"

namespace mmrl {

namespace {

struct PyArriveVecEnv {
  ArriveVecEnv env;
};

py::dict arrive_state_dict(const ArriveVecEnv& env, int i) {
  py::dict d = target_state_dict(env.state(i));
  d["facing"] = env.state(i).target_yaw;
  d["hold"] = env.state(i).hold;
  return d;
}

}  // namespace

void bind_arrive(py::module_& m) {
  bind_task_config<ArriveTaskConfig>(m, "ArriveTaskConfig", "Numbers of the arrive task (see tasks/arrive.hpp).");
  py::class_<PyArriveVecEnv> arrive(m, "ArriveVecEnv", "Batched arrive-task environments (C++ core of mmrl.tasks.arrive).");
  bind_task_env(arrive, arrive_state_dict,
                "Writes into out (int32, N) how many frames of the last step each environment played before its episode "
                "ended: the index of the frame that completed the hold + 1, else frames_per_step (0 after reset).");
  bind_shared_step(arrive);
  arrive.def(
      "set_facing", [](PyArriveVecEnv& s, int i, float yaw) { s.env.set_facing(checked_env_index(s, i), yaw); },
      py::arg("index"), py::arg("yaw"), "Sets env i's target facing (world yaw in radians, finite).");
  arrive.def_property_readonly("hold_frames", [](const PyArriveVecEnv& s) { return s.env.hold_frames(); },
                               "Frames a hold lasts (hold_time at the database's frame rate, at least 1).");
}

}  // namespace mmrl
