// Bindings every batched target-reaching env shares (vecenv.hpp's TargetVecEnv): index
// checks and the methods of the template itself, defined once for each task's class.
// Convert, check, forward; nothing else.
#pragma once

#include <string>

#include "bindings.hpp"
#include "mmrl/vecenv.hpp"

namespace mmrl {

// Env index i of wrapper s (an object with an `env` member), or IndexError naming the range.
template <class Wrapper>
int checked_env_index(const Wrapper& s, int i) {
  if (i < 0 || i >= s.env.num_envs())
    throw py::index_error("env index " + std::to_string(i) + " out of range [0, " + std::to_string(s.env.num_envs()) +
                          ")");
  return i;
}

// The state every target env keeps (world meters, radians), as a dict; tasks add their own keys.
inline py::dict target_state_dict(const TargetEnvState& st) {
  py::dict d;
  d["x"] = st.root.x;
  d["z"] = st.root.z;
  d["yaw"] = st.root.yaw;
  d["frame"] = st.frame;
  d["target"] = py::make_tuple(st.target_x, st.target_z);
  d["steps"] = st.steps;
  d["last_match"] = st.last_match;
  d["last_transition"] = st.last_transition;
  d["last_cost"] = st.last_cost;
  d["last_pose_jump"] = st.last_pose_jump;
  d["last_step_frames"] = st.last_step_frames;
  d["last_step_transition_cost"] = st.last_step_transition_cost;
  d["last_step_match"] = st.last_step_match;
  return d;
}

// current_frames, last_step_frames, last_step_matches, set_state and set_target.
// last_step_frames_doc: what ends a step early in this task.
template <class Wrapper>
void bind_target_env_methods(py::class_<Wrapper>& c, const char* last_step_frames_doc) {
  c.def(
       "current_frames",
       [](const Wrapper& s, const py::handle& out) {
         s.env.current_frames(writable_buffer<int64_t>(out, "out", {s.env.num_envs()}));
       },
       py::arg("out"), "Writes each environment's current database frame into out (int64, N).")
      .def(
          "last_step_frames",
          [](const Wrapper& s, const py::handle& out) {
            s.env.last_step_frames(writable_buffer<int32_t>(out, "out", {s.env.num_envs()}));
          },
          py::arg("out"), last_step_frames_doc)
      .def(
          "last_step_matches",
          [](const Wrapper& s, const py::handle& transitions, const py::handle& costs) {
            const py::ssize_t n = s.env.num_envs();
            uint8_t* t = writable_buffer<uint8_t>(transitions, "transitions", {n});
            float* cost = writable_buffer<float>(costs, "costs", {n});
            s.env.last_step_matches(t, cost);
          },
          py::arg("transitions"), py::arg("costs"),
          "Writes each environment's last step's decision: transitions (uint8, N) 1 where the match was not the "
          "current clip's continuation, costs (float32, N) the match's squared distance to the query (normalized, "
          "weighted feature space). Kept through the autoreset; 0 after reset.")
      .def(
          "last_step_transition_cost",
          [](const Wrapper& s, int i) { return s.env.state(checked_env_index(s, i)).last_step_transition_cost; },
          py::arg("index"),
          "The continuation bias env i's last step matched with (the config's transition_cost, or what the task "
          "made of it for that decision). Kept through the autoreset; 0 after reset.")
      .def(
          "last_step_decision",
          [](const Wrapper& s, int i) {
            const TargetEnvState& st = s.env.state(checked_env_index(s, i));
            return py::make_tuple(st.last_step_match, st.last_step_cost);
          },
          py::arg("index"),
          "(match, cost) of env i's last step: the frame its match chose and the match's cost, what the full path "
          "plays (Character.play). Kept through the autoreset; (-1, 0) after reset and after a NEXT_STEP reset step.")
      .def_property(
          "autoreset_next_step", [](const Wrapper& s) { return s.env.autoreset_next_step(); },
          [](Wrapper& s, bool on) { s.env.set_autoreset_next_step(on); },
          "Autoreset mode: False = SAME_STEP (an ended episode's env is reset in the same step, its last "
          "observation in final_obs), True = NEXT_STEP (the ending step returns the last observation; the next "
          "step ignores the env's action, resets it and returns its first observation with reward 0).")
      .def(
          "set_state",
          [](Wrapper& s, int i, int64_t frame, float x, float z, float yaw) {
            s.env.set_state(checked_env_index(s, i), frame, x, z, yaw);
          },
          py::arg("index"), py::arg("frame"), py::arg("x"), py::arg("z"), py::arg("yaw"),
          "Puts env i on database frame `frame` at world (x, z) facing yaw; keeps its target and episode.")
      .def(
          "set_target",
          [](Wrapper& s, int i, float x, float z) { s.env.set_target(checked_env_index(s, i), x, z); },
          py::arg("index"), py::arg("x"), py::arg("z"), "Moves env i's target (world meters).");
}

}  // namespace mmrl
