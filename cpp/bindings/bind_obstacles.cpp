// Bindings of the moving-obstacles task core (tasks/obstacles.hpp, grid.hpp): checks, GIL
// release, writes into caller-owned numpy buffers. No logic.
#include "bind_task_env.hpp"
#include "bindings.hpp"
#include "mmrl/tasks/obstacles.hpp"

namespace mmrl {

namespace {

struct PyObstacleVecEnv {
  ObstacleVecEnv env;
};

int checked_index(const PyObstacleVecEnv& s, int i) { return checked_env_index(s, i); }

constexpr int kNow = -1;  // obstacle_dict: the obstacles as they are

py::array_t<uint8_t> map_copy(const uint8_t* map) {
  py::array_t<uint8_t> out({kMapSide, kMapSide});
  std::copy(map, map + kMapCells, out.mutable_data());
  return out;
}

// The obstacles() dict: centres (n, 2), half_sizes (n, 2), angles (n), velocities (n, 2),
// now or (frames_after >= 0) after that many played frames.
py::dict obstacle_dict(const ObstacleVecEnv& env, int i, int frames_after) {
  const py::ssize_t n = env.obstacle_count(i);
  py::array_t<float> c({n, py::ssize_t{2}}), h({n, py::ssize_t{2}}), a(n), v({n, py::ssize_t{2}});
  env.obstacles(i, c.mutable_data(), h.mutable_data(), a.mutable_data(), v.mutable_data());
  if (frames_after != kNow) env.obstacles_after(i, frames_after, c.mutable_data(), v.mutable_data());
  py::dict d;
  d["centres"] = c;
  d["half_sizes"] = h;
  d["angles"] = a;
  d["velocities"] = v;
  return d;
}

// The state() dict: the shared keys, the stage and the last action's hit points.
py::dict obstacle_state_dict(const ObstacleVecEnv& env, int i) {
  const ObstacleEnvState& st = env.state(i);
  py::dict d = target_state_dict(st);
  d["max_speed"] = st.max_speed;
  d["target_half_extent"] = st.target_half_extent;
  d["last_hits"] = st.last_hits;
  py::array_t<float> pts({3, 2});
  std::copy(st.hit_points, st.hit_points + 6, pts.mutable_data());
  d["hit_points"] = pts;
  d["hit_inside"] = py::make_tuple(bool(st.hit_inside[0]), bool(st.hit_inside[1]), bool(st.hit_inside[2]));
  d["collided"] = st.collided;
  return d;
}

}  // namespace

// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
void bind_obstacles(py::module_& m) {
  m.attr("OBSTACLE_MAP_SIDE") = kMapSide;
  m.def(
      "trajectory_path",
      [](const py::handle& raw) {
        auto t = check_array<float>(raw, "raw_trajectory", {kTrajectoryDim});
        check_finite(t.data(), kTrajectoryDim, "raw_trajectory");
        py::array_t<float> path({kPathSamples, 2});
        trajectory_path(t.data(), path.mutable_data());
        return path;
      },
      py::arg("raw_trajectory"),
      "The path (PATH_SAMPLE_FRAMES x (x, z), meters, character frame) a raw trajectory (12 floats: "
      "per horizon position then direction) implies: the collision-aware search's path of a compressed "
      "state (tasks/path_filter.hpp's trajectory_path).");
  bind_task_config<ObstacleTaskConfig>(m, "ObstacleTaskConfig", "Numbers of the moving-obstacles task (tasks/obstacles.hpp).");

  using E = ObstacleVecEnv;
  py::class_<PyObstacleVecEnv> obstacles(m, "ObstacleVecEnv",
                                          "Batched moving-obstacles environments (C++ core of mmrl.tasks.obstacles).");
  bind_task_env(obstacles, obstacle_state_dict,
                "Writes into out (int32, N) how many frames of the last step each environment played before its "
                "episode ended: the index of the frame that succeeded or collided + 1, else frames_per_step (0 after "
                "reset).");
  obstacles.def_property_readonly_static("layout", [](py::object) {
        return py::make_tuple(py::make_tuple("maps", 2 * kMapCells), py::make_tuple("pose", kPoseDim),
                              py::make_tuple("goal", 2));
      })
      .def(
          "set_stage",
          [](PyObstacleVecEnv& s, float max_speed, float target_half_extent) {
            try {
              s.env.set_stage(max_speed, target_half_extent);
            } catch (const std::invalid_argument& e) {
              throw py::value_error(e.what());
            }
          },
          py::arg("max_speed"), py::arg("target_half_extent"),
          "The stage (obstacle max speed m/s, target square half-extent m) for every env's next reset.")
      .def_property_readonly("stage", [](const PyObstacleVecEnv& s) {
        return py::make_tuple(s.env.stage_max_speed(), s.env.stage_target_half_extent());
      })
      .def(
          "step",
          [](PyObstacleVecEnv& s, const py::handle& actions, const py::handle& obs, const py::handle& rewards,
             const py::handle& terminated, const py::handle& truncated, const py::handle& success,
             const py::handle& collision, const py::handle& hits, const py::handle& final_obs,
             const py::handle& episode_return, const py::handle& episode_length, const py::handle& step_frames,
             const py::handle& transitions, const py::handle& costs, const py::handle& episode_frames) {
            const py::ssize_t n = s.env.num_envs();
            auto a = step_actions(s.env, actions);
            const TargetStepBuffers out = step_buffers(s.env, obs, rewards, terminated, truncated, success, final_obs,
                                                       episode_return, episode_length, step_frames, transitions, costs,
                                                   episode_frames);
            uint8_t* co = writable_buffer<uint8_t>(collision, "collision", {n});
            int32_t* hi = writable_buffer<int32_t>(hits, "hits", {n});
            py::gil_scoped_release release;
            s.env.step(a.data(), out, co, hi);
          },
          py::arg("actions"), py::arg("obs"), py::arg("rewards"), py::arg("terminated"), py::arg("truncated"),
          py::arg("success"), py::arg("collision"), py::arg("hits"), py::arg("final_obs"), py::arg("episode_return"),
          py::arg("episode_length"), py::arg("step_frames") = py::none(), py::arg("transitions") = py::none(),
          py::arg("costs") = py::none(), py::arg("episode_frames") = py::none(),
          "One step of every env (actions float32 N x 12, finite), writing every buffer; collision (uint8, N) and "
          "hits (int32, N) are the task's. step_frames (int32, N), transitions (uint8, N) and costs (float32, N), if "
          "given, get every env's step_frames and last_step_transitions, and episode_frames (int64, N) where an "
          "episode ended the frames it played: one call returns all a step produced.")
      .def(
          "obstacles", [](const PyObstacleVecEnv& s, int i) { return obstacle_dict(s.env, checked_index(s, i), kNow); },
          py::arg("index"),
          "Obstacles of env i (world meters): centres (n,2) as (x,z), half_sizes (n,2) along the obstacle's own X/Z, "
          "angles (n) in radians (yaw convention), velocities (n,2) m/s.")
      .def(
          "obstacles_after",
          [](const PyObstacleVecEnv& s, int i, int frames) {
            if (frames < 0) throw py::value_error("frames: must be >= 0, got " + std::to_string(frames));
            return obstacle_dict(s.env, checked_index(s, i), frames);
          },
          py::arg("index"), py::arg("frames"),
          "Env i's obstacles (the obstacles() dict) after `frames` more played frames of the env's own motion "
          "(constant velocity, bounce at the square's border), bit for bit as steps move them. Called at a step's "
          "start with frames = step_frames, it gives the obstacles at the step's end.")
      .def(
          "set_obstacles",
          [](PyObstacleVecEnv& s, int i, const py::handle& centres, const py::handle& half_sizes,
             const py::handle& angles, const py::handle& velocities) {
            checked_index(s, i);
            auto c = check_array<float>(centres, "centres", {-1, 2});
            const py::ssize_t n = c.shape(0);
            auto h = check_array<float>(half_sizes, "half_sizes", {n, 2});
            auto a = check_array<float>(angles, "angles", {n});
            auto v = check_array<float>(velocities, "velocities", {n, 2});
            s.env.set_obstacles(i, static_cast<int>(n), c.data(), h.data(), a.data(), v.data());
          },
          py::arg("index"), py::arg("centres"), py::arg("half_sizes"), py::arg("angles"), py::arg("velocities"),
          "Replace env i's obstacles (float32 arrays); refreshes its grid and current sensor map.")
      .def(
          "sensor_map",
          [](const PyObstacleVecEnv& s, int i, bool previous) {
            checked_index(s, i);
            return map_copy(previous ? s.env.previous_sensor_map(i) : s.env.sensor_map(i));
          },
          py::arg("index"), py::arg("previous") = false, "Env i's current (or previous) 16 x 16 map, uint8 [row][col].")
      .def(
          "sensor_map_bruteforce",
          [](const PyObstacleVecEnv& s, int i) {
            checked_index(s, i);
            py::array_t<uint8_t> out({kMapSide, kMapSide});
            s.env.sensor_map_bruteforce(i, out.mutable_data());
            return out;
          },
          py::arg("index"), "Env i's map now, every sensor tested against every obstacle (reference).")
      .def(
          "sensor_positions",
          [](const PyObstacleVecEnv& s, int i) {
            checked_index(s, i);
            py::array_t<float> out({kMapSide, kMapSide, 2});
            s.env.sensor_positions(i, out.mutable_data());
            return out;
          },
          py::arg("index"), "World (x, z) of env i's sensors, (16, 16, 2) [row][col].")
      .def(
          "action_hits",
          [](const PyObstacleVecEnv& s, int i, const py::handle& action) {
            checked_index(s, i);
            auto a = check_array<float>(action, "action", {E::kActionDim});
            check_finite(a.data(), a.size(), "action");
            py::array_t<float> pts({3, 2});
            uint8_t inside[3];
            const int hits = s.env.action_hits(i, a.data(), pts.mutable_data(), inside);
            return py::make_tuple(hits, pts, py::make_tuple(bool(inside[0]), bool(inside[1]), bool(inside[2])));
          },
          py::arg("index"), py::arg("action"),
          "(hits, world points (3,2), inside flags) of a normalized action for env i's current state.")
      .def(
          "path_hits",
          [](PyObstacleVecEnv& s, int i, const py::handle& rows) {
            checked_index(s, i);
            auto r = check_array<int64_t>(rows, "rows", {-1});
            py::array_t<int32_t> out(r.shape(0));
            s.env.path_hits(i, r.data(), static_cast<int>(r.shape(0)), out.mutable_data());
            return out;
          },
          py::arg("index"), py::arg("rows"),
          "For env i's current state, each database row's collision-aware path test "
          "(tasks/path_filter.hpp, this env's path options): the frames ahead of its path's first hit, "
          "0 when clear.")
      .def(
          "state_path_hits",
          [](PyObstacleVecEnv& s, int i, const py::handle& features) {
            checked_index(s, i);
            auto f = check_array<float>(features, "features", {-1, kFeatureDim});
            py::array_t<int32_t> out(f.shape(0));
            s.env.state_path_hits(i, f.data(), static_cast<int>(f.shape(0)), out.mutable_data());
            return out;
          },
          py::arg("index"), py::arg("features"),
          "The same test of compressed states known by their normalized features (N, 27): each path is "
          "the quadratic through the start and the state's three trajectory positions (path_filter.hpp's "
          "trajectory_path); the frames ahead of its first hit, 0 when clear.")
      .def(
          "collides",
          [](const PyObstacleVecEnv& s, int i, float x, float z) {
            return s.env.collides(checked_index(s, i), x, z);
          },
          py::arg("index"), py::arg("x"), py::arg("z"), "Whether the body disc at world (x, z) overlaps an obstacle.")
      .def(
          "set_root",
          [](PyObstacleVecEnv& s, int i, float x, float z, float yaw) {
            s.env.set_root(checked_index(s, i), x, z, yaw);
          },
          py::arg("index"), py::arg("x"), py::arg("z"), py::arg("yaw"));
}

}  // namespace mmrl
