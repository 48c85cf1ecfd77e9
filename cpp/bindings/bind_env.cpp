// Bindings of the plane task (tasks/plane.hpp): checks, GIL release, writes into caller-owned
// numpy buffers. No logic.
#include "bind_target_env.hpp"
#include "bindings.hpp"
#include "mmrl/tasks/plane.hpp"
#include "py_matcher.hpp"

namespace mmrl {

namespace {

// The env borrows the database and the matcher; keep_alive holds their Python owners.
struct PyPlaneVecEnv {
  PlaneVecEnv env;
};

}  // namespace

// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
void bind_env(py::module_& m) {
  py::class_<TargetTaskConfig>(m, "TargetTaskConfig", "Numbers of the plane task (see tasks/plane.hpp).")
      .def(py::init<>())
      .def_readwrite("frames_per_step", &TargetTaskConfig::frames_per_step)
      .def_readwrite("target_half_extent", &TargetTaskConfig::target_half_extent)
      .def_readwrite("min_target_distance", &TargetTaskConfig::min_target_distance)
      .def_readwrite("success_radius", &TargetTaskConfig::success_radius)
      .def_readwrite("success_bonus", &TargetTaskConfig::success_bonus)
      .def_readwrite("max_steps", &TargetTaskConfig::max_steps)
      .def_readwrite("action_limit_std", &TargetTaskConfig::action_limit_std)
      .def_readwrite("random_heading", &TargetTaskConfig::random_heading)
      .def_readwrite("transition_cost", &TargetTaskConfig::transition_cost)
      .def_readwrite("clip_costs", &TargetTaskConfig::clip_costs)
      .def_readwrite("transition_pose_weight", &TargetTaskConfig::transition_pose_weight);

  py::class_<PyPlaneVecEnv> plane(m, "PlaneVecEnv", "Batched plane-task environments (C++ core of mmrl.tasks.plane).");
  plane.def(py::init([](const Database& db, PyMatcher& matcher, int num_envs, const TargetTaskConfig& config,
                       int num_threads) {
             if (num_threads < 0) throw py::value_error("num_threads: must be >= 0 (0 = all cores)");
             return new PyPlaneVecEnv{PlaneVecEnv(db, matcher.matcher, num_envs, config, num_threads)};
           }),
           py::arg("db"), py::arg("matcher"), py::arg("num_envs"), py::arg("config"), py::arg("num_threads") = 0,
           py::keep_alive<1, 2>(), py::keep_alive<1, 3>())
      .def_property_readonly("num_envs", [](const PyPlaneVecEnv& s) { return s.env.num_envs(); })
      .def_property_readonly_static("obs_dim", [](py::object) { return PlaneVecEnv::kObsDim; })
      .def_property_readonly_static("action_dim", [](py::object) { return PlaneVecEnv::kActionDim; })
      .def_property_readonly("action_low",
                             [](const PyPlaneVecEnv& s) { return py::array_t<float>(kTrajectoryDim, s.env.action_low()); })
      .def_property_readonly("action_high",
                             [](const PyPlaneVecEnv& s) { return py::array_t<float>(kTrajectoryDim, s.env.action_high()); })
      .def(
          "reset",
          [](PyPlaneVecEnv& s, uint64_t seed, const py::handle& obs) {
            float* o = writable_buffer<float>(obs, "obs", {s.env.num_envs(), PlaneVecEnv::kObsDim});
            py::gil_scoped_release release;
            s.env.reset(seed, o);
          },
          py::arg("seed"), py::arg("obs"))
      .def(
          "reset_env",
          [](PyPlaneVecEnv& s, int i, const py::handle& obs) {
            if (i < 0 || i >= s.env.num_envs()) throw py::index_error("env index out of range");
            float* o = writable_buffer<float>(obs, "obs", {s.env.num_envs(), PlaneVecEnv::kObsDim});
            s.env.reset_env(i, o + static_cast<size_t>(i) * PlaneVecEnv::kObsDim);
          },
          py::arg("index"), py::arg("obs"))
      .def(
          "step",
          [](PyPlaneVecEnv& s, const py::handle& actions, const py::handle& obs, const py::handle& rewards,
             const py::handle& terminated, const py::handle& truncated, const py::handle& success,
             const py::handle& final_obs, const py::handle& episode_return, const py::handle& episode_length) {
            const py::ssize_t n = s.env.num_envs();
            auto a = check_array<float>(actions, "actions", {n, PlaneVecEnv::kActionDim});
            check_finite(a.data(), a.size(), "actions");
            float* o = writable_buffer<float>(obs, "obs", {n, PlaneVecEnv::kObsDim});
            float* r = writable_buffer<float>(rewards, "rewards", {n});
            uint8_t* te = writable_buffer<uint8_t>(terminated, "terminated", {n});
            uint8_t* tr = writable_buffer<uint8_t>(truncated, "truncated", {n});
            uint8_t* su = writable_buffer<uint8_t>(success, "success", {n});
            float* fo = writable_buffer<float>(final_obs, "final_obs", {n, PlaneVecEnv::kObsDim});
            float* er = writable_buffer<float>(episode_return, "episode_return", {n});
            int32_t* el = writable_buffer<int32_t>(episode_length, "episode_length", {n});
            py::gil_scoped_release release;
            s.env.step(a.data(), o, r, te, tr, su, fo, er, el);
          },
          py::arg("actions"), py::arg("obs"), py::arg("rewards"), py::arg("terminated"), py::arg("truncated"),
          py::arg("success"), py::arg("final_obs"), py::arg("episode_return"), py::arg("episode_length"))
      .def(
          "state",
          [](const PyPlaneVecEnv& s, int i) {
            return target_state_dict(s.env.state(checked_env_index(s, i)));
          },
          py::arg("index"), "The world-space state of environment i (root, frame, target).")
      .def(
          "observe",
          [](const PyPlaneVecEnv& s, int i, const py::handle& out) {
            if (i < 0 || i >= s.env.num_envs()) throw py::index_error("env index out of range");
            float* o = writable_buffer<float>(out, "out", {PlaneVecEnv::kObsDim});
            s.env.observe(i, o);
          },
          py::arg("index"), py::arg("out"), "Writes environment i's current observation into out (float32, 17).");
  bind_target_env_methods(plane,
                          "Writes into out (int32, N) how many frames of the last step each environment played "
                          "before its episode ended: the index of the first frame within success_radius + 1, else "
                          "frames_per_step (0 after reset).");
}

}  // namespace mmrl
