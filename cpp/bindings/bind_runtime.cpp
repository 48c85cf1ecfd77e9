// mmrl_runtime for tests and tools: load a controller file, step characters. Convert, check, forward.
#include "bindings.hpp"
#include "mmrl/runtime.hpp"

namespace mmrl {

namespace {

py::array copy_array(const float* data, std::vector<py::ssize_t> shape) {
  py::array_t<float> a(shape);
  std::copy(data, data + a.size(), a.mutable_data());
  return std::move(a);
}

py::dict decision_dict(const RuntimeDecision& d) {
  py::dict out;
  out["count"] = d.count;
  out["frames_before"] = d.frames_before;
  out["root_before"] = py::make_tuple(d.root_before.x, d.root_before.z, d.root_before.yaw);
  out["target"] = py::make_tuple(d.target_x, d.target_z);
  out["match"] = d.match;
  out["transition"] = d.transition;
  out["cost"] = d.cost;
  out["stick"] = d.stick;
  return out;
}

}  // namespace

// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
void bind_runtime(py::module_& m) {
  m.def(
      "runtime_task_cores",
      [] {
        py::list out;
        for (const RuntimeTaskType& t : runtime_task_types()) out.append(t.core);
        return py::tuple(out);
      },
      "The task cores the engine runtime has registered (runtime_task.hpp), in registration order.");
  py::register_exception<ControllerFileError>(m, "ControllerFileError", PyExc_ValueError);
  // pybind11 holders cannot be pointers to const; the controller is never changed through it.
  using ControllerPtr = std::shared_ptr<RuntimeController>;
  py::class_<RuntimeController, ControllerPtr>(m, "RuntimeController",
                                               "A loaded controller file (runtime.hpp), shared by characters.")
      .def_static(
          "load",
          [](const std::string& path, bool require_path_filter) {
            py::gil_scoped_release release;
            RuntimeLoadOptions options;
            options.require_path_filter = require_path_filter;
            return std::const_pointer_cast<RuntimeController>(RuntimeController::load(path, options));
          },
          py::arg("path"), py::arg("require_path_filter") = false,
          "Loads and checks a controller file; require_path_filter refuses one without the obstacles "
          "task's collision-aware search.")
      .def_property_readonly("num_joints", &RuntimeController::num_joints)
      .def_property_readonly("num_frames", [](const RuntimeController& c) { return c.database().num_frames; })
      .def_property_readonly("fps", &RuntimeController::fps)
      .def_property_readonly("obs_dim", [](const RuntimeController& c) { return c.policy().obs_dim(); })
      .def_property_readonly("task_name", [](const RuntimeController& c) { return c.task().name; })
      .def_property_readonly("task_core", [](const RuntimeController& c) { return c.task().core; },
                             "The registered task core the file's task runs on (runtime_task.hpp).")
      .def_property_readonly(
          "obs_layout",
          [](const RuntimeController& c) {
            py::list out;
            for (const ObsSegment& s : c.task().layout) out.append(py::make_tuple(s.name, s.size));
            return py::tuple(out);
          },
          "The policy's observation, segment by segment: a tuple of (name, size).")
      .def_property_readonly("frames_per_step", [](const RuntimeController& c) { return c.task().frames_per_step; })
      .def_property_readonly("memory_bytes", &RuntimeController::memory_bytes)
      .def_property_readonly("compressed", [](const RuntimeController& c) { return c.motion_source() != nullptr; },
                             "True for a compressed controller (networks in place of the database).")
      .def(
          "act",
          [](const RuntimeController& c, const py::handle& obs) {
            auto o = check_array<float>(obs, "obs", {c.policy().obs_dim()});
            PolicyScratch scratch = c.policy().make_scratch();
            py::array_t<float> action(c.policy().act_dim());
            c.policy().act(o.data(), action.mutable_data(), scratch);
            return action;
          },
          py::arg("obs"), "The policy's deterministic action for one raw observation (policy_net.hpp).");

  py::class_<RuntimeCharacter>(m, "RuntimeCharacter", "A character driven by a loaded controller (runtime.hpp).")
      .def(py::init([](ControllerPtr c, float x, float z, float yaw, int64_t start_frame) {
             return new RuntimeCharacter(std::move(c), x, z, yaw, start_frame);
           }),
           py::arg("controller"), py::arg("x"), py::arg("z"), py::arg("yaw"), py::arg("start_frame") = -1)
      .def("set_target", &RuntimeCharacter::set_target, py::arg("x"), py::arg("z"),
           "The target (world meters) from the next decision on; switches a stick off.")
      .def("set_facing", &RuntimeCharacter::set_facing, py::arg("yaw"),
           "The facing to arrive with (world yaw in radians, 0 faces +Z) from the next decision on, for a task that "
           "reads one (takes_facing: the arrive task, which refuses to decide until it is set).")
      .def_property_readonly("takes_facing", &RuntimeCharacter::takes_facing)
      .def("set_stick", &RuntimeCharacter::set_stick, py::arg("x"), py::arg("z"), py::arg("speed"),
           "A stick in place of the target and the policy, from the next decision on: a world direction (x, z; any "
           "length > 0) and a speed (m/s > 0); the scripted joystick's action. ValueError naming a bad argument.")
      .def_property_readonly("stick", &RuntimeCharacter::stick)
      .def(
          "stick_action",
          [](const RuntimeCharacter& ch) {
            py::array_t<float> action(kTrajectoryDim);
            ch.stick_action(action.mutable_data());
            return action;
          },
          "The stick's action (12 normalized floats) for the heading now, as the next decision takes it.")
      .def("set_request", &RuntimeCharacter::set_request, py::arg("request"),
           "A request over the file's tags ('style=elderly & gait=walk'; '' for every clip), from the next decision "
           "on. ValueError naming an unknown tag (the file's tags listed) or a request selecting no valid frame.")
      .def_property_readonly("request", &RuntimeCharacter::request)
      .def(
          "set_obstacles",
          [](RuntimeCharacter& ch, const py::handle& centres, const py::handle& half_sizes, const py::handle& angles,
             const py::handle& velocities) {
            auto c = check_array<float>(centres, "centres", {-1, 2});
            const py::ssize_t n = c.shape(0);
            auto h = check_array<float>(half_sizes, "half_sizes", {n, 2});
            auto a = check_array<float>(angles, "angles", {n});
            if (velocities.is_none()) {
              ch.set_obstacles(static_cast<int>(n), c.data(), h.data(), a.data());
            } else {
              auto v = check_array<float>(velocities, "velocities", {n, 2});
              ch.set_obstacles(static_cast<int>(n), c.data(), h.data(), a.data(), v.data());
            }
          },
          py::arg("centres"), py::arg("half_sizes"), py::arg("angles"), py::arg("velocities") = py::none(),
          "The obstacles now (world meters, radians; float32) and, optionally, their velocities (m/s; None: "
          "standing still), read at the next decision.")
      .def("advance_frame", [](RuntimeCharacter& ch) { ch.advance_frame(); })
      .def("update", [](RuntimeCharacter& ch, float dt) { ch.update(dt); }, py::arg("dt"))
      .def_property_readonly("frame", [](const RuntimeCharacter& ch) { return ch.pose().frame; })
      .def_property_readonly("root", [](const RuntimeCharacter& ch) {
        return py::make_tuple(ch.pose().root.x, ch.pose().root.z, ch.pose().root.yaw);
      })
      .def_property_readonly("frames_shown", &RuntimeCharacter::frames_shown)
      .def("global_positions",
           [](const RuntimeCharacter& ch) { return copy_array(ch.pose().global_positions, {ch.pose().num_joints, 3}); })
      .def("local_rotations",
           [](const RuntimeCharacter& ch) { return copy_array(ch.pose().local_rotations, {ch.pose().num_joints, 4}); })
      .def("local_translations", [](const RuntimeCharacter& ch) {
        return copy_array(ch.pose().local_translations, {ch.pose().num_joints, 3});
      })
      .def("last_decision", [](const RuntimeCharacter& ch) { return decision_dict(ch.last_decision()); })
      .def("observe", [](RuntimeCharacter& ch) {
        return copy_array(ch.observe(), {static_cast<py::ssize_t>(ch.controller().policy().obs_dim())});
      });
}

}  // namespace mmrl
