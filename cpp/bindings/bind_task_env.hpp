// Bindings every batched target-reaching task shares (vecenv.hpp's TargetVecEnv and
// tasks/task_config.hpp): the config class from its field table, the env's constructor,
// reset, observe, state and the template's own methods, and the step's shared buffers. A
// task's binding file adds only its step signature and its own methods. Convert, check,
// forward; nothing else.
#pragma once

#include <string>
#include <type_traits>

#include "bind_compressed.hpp"
#include "mmrl/vecenv.hpp"
#include "py_matcher.hpp"

namespace mmrl {

// An observation layout as Python reads it: a tuple of (name, size).
inline py::tuple layout_tuple(const ObsLayout& layout) {
  py::list out;
  for (const ObsSegment& s : layout) out.append(py::make_tuple(s.name, s.size));
  return py::tuple(out);
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
  d["last_match"] = st.decision.match;
  d["last_transition"] = st.decision.transition;
  d["last_cost"] = st.decision.cost;
  d["last_pose_jump"] = st.decision.pose_jump;
  d["step_frames"] = st.step_frames;
  d["last_step_frames"] = st.step_frames;  // the old key of step_frames, for one release
  d["last_step_transition_cost"] = st.last_step.transition_cost;
  d["last_step_match"] = st.last_step.match;
  return d;
}

// A task's config class: a default constructor, every field of Config::visit as a property
// with its doc, and the option table `options`: a tuple of (name, kind, default, lo, hi,
// lo_open, inf_ok, doc) per field, kind one of "int", "float", "bool", "floats", "texts" (what
// python/mmrl/tasks/options.py builds the Python config from), and its retired options.
template <class Config>
py::class_<Config> bind_task_config(py::module_& m, const char* name, const char* doc) {
  py::class_<Config> c(m, name, doc);
  c.def(py::init<>());
  py::list names, options;
  const Config defaults;
  Config::visit([&](const char* field, auto member, const OptionRange& range, const char* field_doc) {
    using T = typename std::decay<decltype(defaults.*member)>::type;
    c.def_readwrite(field, member, field_doc);
    names.append(field);
    const char* kind = std::is_same<T, bool>::value ? "bool"
                       : std::is_integral<T>::value ? "int"
                       : std::is_floating_point<T>::value ? "float"
                       : std::is_same<T, std::vector<float>>::value ? "floats" : "texts";
    options.append(py::make_tuple(field, kind, py::cast(defaults.*member), range.lo, range.hi, range.lo_open,
                                  range.inf_ok, field_doc));
  });
  c.attr("field_names") = py::tuple(names);
  c.attr("options") = py::tuple(options);
  py::dict retired;  // name -> the value the code now always runs (task_config.hpp's RetiredOption)
  for (const RetiredOption& r : Config::retired()) retired[r.name] = r.now;
  c.attr("retired") = retired;
  return c;
}

// The actions of a step (N x kActionDim float32, finite: the one finiteness check of a step).
template <class Env>
carray<float> step_actions(const Env& env, const py::handle& actions) {
  auto a = check_array<float>(actions, "actions", {env.num_envs(), Env::kActionDim});
  check_finite(a.data(), a.size(), "actions");
  return a;
}

// The shared step buffers, checked (the last three may be None: not written).
template <class Env>
TargetStepBuffers step_buffers(const Env& env, const py::handle& obs, const py::handle& rewards,
                               const py::handle& terminated, const py::handle& truncated, const py::handle& success,
                               const py::handle& final_obs, const py::handle& episode_return,
                               const py::handle& episode_length, const py::handle& step_frames,
                               const py::handle& transitions, const py::handle& costs,
                               const py::handle& episode_frames) {
  const py::ssize_t n = env.num_envs();
  TargetStepBuffers out{writable_buffer<float>(obs, "obs", {n, env.obs_dim()}),
                        writable_buffer<float>(rewards, "rewards", {n}),
                        writable_buffer<uint8_t>(terminated, "terminated", {n}),
                        writable_buffer<uint8_t>(truncated, "truncated", {n}),
                        writable_buffer<uint8_t>(success, "success", {n}),
                        writable_buffer<float>(final_obs, "final_obs", {n, env.obs_dim()}),
                        writable_buffer<float>(episode_return, "episode_return", {n}),
                        writable_buffer<int32_t>(episode_length, "episode_length", {n})};
  if (!step_frames.is_none()) out.step_frames = writable_buffer<int32_t>(step_frames, "step_frames", {n});
  if (!transitions.is_none()) out.transitions = writable_buffer<uint8_t>(transitions, "transitions", {n});
  if (!costs.is_none()) out.costs = writable_buffer<float>(costs, "costs", {n});
  if (!episode_frames.is_none()) out.episode_frames = writable_buffer<int64_t>(episode_frames, "episode_frames", {n});
  return out;
}

// The methods every task env has: construction from (db, matcher, num_envs, config,
// num_threads), its sizes and action box, reset, reset_env, observe (into a buffer), state
// (state_dict(env, i): the shared keys and the task's own), current_frames, step_frames,
// last_step_transitions, last_step_decision, last_step_transition_cost, the autoreset mode,
// set_state and set_target. step_frames_doc: what ends a step early in this task.
// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
template <class Wrapper, class StateDict>
void bind_task_env(py::class_<Wrapper>& c, StateDict state_dict, const char* step_frames_doc) {
  using Env = decltype(std::declval<Wrapper&>().env);
  using Config = typename std::decay<decltype(std::declval<const Env&>().config())>::type;
  c.def(py::init([](const Database& db, PyMatcher& matcher, int num_envs, const Config& config, int num_threads) {
         if (num_threads < 0) throw py::value_error("num_threads: must be >= 0 (0 = all cores)");
         if (num_envs < 1) throw py::value_error("num_envs: must be >= 1");
         return new Wrapper{Env(db, matcher.matcher, num_envs, config, num_threads)};
       }),
       py::arg("db"), py::arg("matcher"), py::arg("num_envs"), py::arg("config"), py::arg("num_threads") = 0,
       py::keep_alive<1, 2>(), py::keep_alive<1, 3>())
      .def_property_readonly("num_envs", [](const Wrapper& s) { return s.env.num_envs(); })
      .def_property_readonly_static("core_name", [](py::object) { return std::string(Env::kCoreName); })
      .def_property_readonly_static("plays_compressed", [](py::object) { return true; })
      .def_property_readonly("obs_dim", [](const Wrapper& s) { return s.env.obs_dim(); })
      .def_property_readonly(
          "obs_layout", [](const Wrapper& s) { return layout_tuple(s.env.obs_layout()); },
          "This env's observation, segment by segment: a tuple of (name, size) in order (the task's own, then "
          "'request' with request_groups).")
      .def_property_readonly_static("action_dim", [](py::object) { return Env::kActionDim; })
      .def_property_readonly("action_low",
                             [](const Wrapper& s) { return py::array_t<float>(kTrajectoryDim, s.env.action_low()); })
      .def_property_readonly("action_high",
                             [](const Wrapper& s) { return py::array_t<float>(kTrajectoryDim, s.env.action_high()); })
      .def(
          "reset",
          [](Wrapper& s, uint64_t seed, const py::handle& obs) {
            float* o = writable_buffer<float>(obs, "obs", {s.env.num_envs(), s.env.obs_dim()});
            py::gil_scoped_release release;
            s.env.reset(seed, o);
          },
          py::arg("seed"), py::arg("obs"))
      .def(
          "reset_env",
          [](Wrapper& s, int i, const py::handle& obs) {
            checked_env_index(s, i);
            float* o = writable_buffer<float>(obs, "obs", {s.env.num_envs(), s.env.obs_dim()});
            s.env.reset_env(i, o + static_cast<size_t>(i) * s.env.obs_dim());
          },
          py::arg("index"), py::arg("obs"))
      .def(
          "observe",
          [](const Wrapper& s, int i, const py::handle& out) {
            checked_env_index(s, i);
            s.env.observe(i, writable_buffer<float>(out, "out", {s.env.obs_dim()}));
          },
          py::arg("index"), py::arg("out"), "Writes environment i's current observation into out (float32, obs_dim).")
      .def(
          "state", [state_dict](const Wrapper& s, int i) { return state_dict(s.env, checked_env_index(s, i)); },
          py::arg("index"), "The world-space state of environment i (root, frame, target and the task's own).")
      .def(
       "current_frames",
       [](const Wrapper& s, const py::handle& out) {
         s.env.current_frames(writable_buffer<int64_t>(out, "out", {s.env.num_envs()}));
       },
       py::arg("out"), "Writes each environment's current database frame into out (int64, N).")
      .def(
          "step_frames",
          [](const Wrapper& s, const py::handle& out) {
            s.env.step_frames(writable_buffer<int32_t>(out, "out", {s.env.num_envs()}));
          },
          py::arg("out"), step_frames_doc)
      .def(
          "last_step_transitions",
          [](const Wrapper& s, const py::handle& transitions, const py::handle& costs) {
            const py::ssize_t n = s.env.num_envs();
            uint8_t* t = writable_buffer<uint8_t>(transitions, "transitions", {n});
            float* cost = writable_buffer<float>(costs, "costs", {n});
            s.env.last_step_transitions(t, cost);
          },
          py::arg("transitions"), py::arg("costs"),
          "Writes each environment's last step's decision: transitions (uint8, N) 1 where the match was not the "
          "current clip's continuation, costs (float32, N) the match's squared distance to the query (normalized, "
          "weighted feature space). Kept through the autoreset; 0 after reset.")
      .def(
          "last_step_transition_cost",
          [](const Wrapper& s, int i) { return s.env.state(checked_env_index(s, i)).last_step.transition_cost; },
          py::arg("index"),
          "The transition cost env i's last step matched with (the config's transition_cost, or what the task "
          "made of it for that decision). Kept through the autoreset; 0 after reset.")
      .def(
          "pop_match_stats",
          [](Wrapper& s) {
            const MatchStats t = s.env.pop_match_stats();
            py::dict d;
            d["decisions"] = t.decisions;
            d["transitions"] = t.transitions;
            d["cost_sum"] = t.cost_sum;
            d["frames"] = t.frames;
            return d;
          },
          "Every env's decisions since the last call, summed, then zeroed: decisions (steps that matched), "
          "transitions, cost_sum (their matched costs) and frames (played, each step up to its ending frame).")
      .def(
          "last_step_decision",
          [](const Wrapper& s, int i) {
            const TargetEnvState& st = s.env.state(checked_env_index(s, i));
            return py::make_tuple(st.last_step.match, st.last_step.cost);
          },
          py::arg("index"),
          "(match, cost) of env i's last step: the frame its match chose and the match's cost, what the full path "
          "plays (Character.play). Kept through the autoreset; (-1, 0) after reset and after a NEXT_STEP reset step.")
      .def(
          "last_step_anchor",
          [](const Wrapper& s, int i) {
            const TargetEnvState& st = s.env.state(checked_env_index(s, i));
            return py::make_tuple(st.last_step.anchor[0], st.last_step.anchor[1]);
          },
          py::arg("index"),
          "(dx, dz) the root moved by at env i's last step's transition to keep the planted feet (character frame, "
          "meters; the task's anchor option), (0, 0) without one: what Character.play takes as anchor.")
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
          "draw_target_around_root",
          [](Wrapper& s, int i, float half_extent) {
            const int e = checked_env_index(s, i);
            s.env.draw_target_around_root(e, half_extent);
            return py::make_tuple(s.env.state(e).target_x, s.env.state(e).target_z);
          },
          py::arg("index"), py::arg("half_extent"),
          "Draws env i a new target by the episode start's rule around where it stands now (its own RNG); "
          "returns it (world x, z).")
      .def(
          "set_target",
          [](Wrapper& s, int i, float x, float z) { s.env.set_target(checked_env_index(s, i), x, z); },
          py::arg("index"), py::arg("x"), py::arg("z"), "Moves env i's target (world meters).")
      .def_property_readonly("request_dim", [](const Wrapper& s) { return s.env.request_dim(); },
                             "Floats of the request code at the end of each observation (0 without request_groups).")
      .def_property_readonly("request_groups", [](const Wrapper& s) { return s.env.request_code().groups(); })
      .def(
          "set_request",
          [](Wrapper& s, int i, const std::string& text) { s.env.set_request(checked_env_index(s, i), text); },
          py::arg("index"), py::arg("request"),
          "Pins env i's request ('style=elderly & gait=walk'; '' unpins): its matches and episode starts keep to the "
          "clips carrying it from the next decision on. ValueError naming an unknown tag, or when it selects no "
          "valid frame (listing the tags available).")
      .def(
          "request",
          [](const Wrapper& s, int i) { return s.env.request(checked_env_index(s, i)).request.text; },
          py::arg("index"), "Env i's request now, as canonical text ('' = every clip).")
      .def(
          "request_mix",
          [](const Wrapper& s) {
            const RequestMix& mix = s.env.request_mix();
            py::list out;
            for (size_t k = 0; k < mix.selections.size(); ++k)
              out.append(py::make_tuple(mix.selections[k].request.text,
                                        mix.cumulative[k] - (k ? mix.cumulative[k - 1] : 0.0)));
            return out;
          },
          "The requests training draws per episode: (text, probability) pairs ([] without request_groups).");
  bind_compressed_env(c);  // set_compressed and the compressed state's accessors (bind_compressed.hpp)
}

// The step of a task whose outputs are the shared ones (TargetStepBuffers): the plane task's,
// the arrive task's.
template <class Wrapper>
void bind_shared_step(py::class_<Wrapper>& c) {
  c.def(
      "step",
      [](Wrapper& s, const py::handle& actions, const py::handle& obs, const py::handle& rewards,
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
