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
  plane.def(
      "step",
      [](PyPlaneVecEnv& s, const py::handle& actions, const py::handle& obs, const py::handle& rewards,
         const py::handle& terminated, const py::handle& truncated, const py::handle& success,
         const py::handle& final_obs, const py::handle& episode_return, const py::handle& episode_length,
         const py::handle& step_frames, const py::handle& transitions, const py::handle& costs,
         const py::handle& episode_frames) {
        auto a = step_actions(s.env, actions);
        const TargetStepBuffers out = step_buffers(s.env, obs, rewards, terminated, truncated, success, final_obs,
                                                   episode_return, episode_length, step_frames, transitions, costs,
                                                   episode_frames);
        py::gil_scoped_release release;
        s.env.step(a.data(), out);
      },
      py::arg("actions"), py::arg("obs"), py::arg("rewards"), py::arg("terminated"), py::arg("truncated"),
      py::arg("success"), py::arg("final_obs"), py::arg("episode_return"), py::arg("episode_length"),
      py::arg("step_frames") = py::none(), py::arg("transitions") = py::none(), py::arg("costs") = py::none(),
      py::arg("episode_frames") = py::none(),
      "One step of every env (actions float32 N x 12, finite), writing every buffer. step_frames (int32, N), "
      "transitions (uint8, N) and costs (float32, N), if given, get every env's step_frames and "
      "last_step_transitions, and episode_frames (int64, N) where an episode ended the frames it played: one call "
      "returns all a step produced.");
}

}  // namespace mmrl
