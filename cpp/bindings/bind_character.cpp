#include "bindings.hpp"
#include "mmrl/character.hpp"
#include "mmrl/compressed_source.hpp"
#include "mmrl/database_source.hpp"
#include "py_matcher.hpp"

namespace mmrl {

namespace {

Vec3 vec3_arg(const py::handle& obj, const char* name) {
  auto a = check_array<float>(obj, name, {3});
  check_finite(a.data(), 3, name);
  return Vec3(a.data()[0], a.data()[1], a.data()[2]);
}

py::array quat_array(const Quat& q) {
  py::array_t<float> a(4);
  quat_store(q, a.mutable_data());
  return std::move(a);
}

py::array vec_array(const Vec3& v) {
  py::array_t<float> a(3);
  for (int k = 0; k < 3; ++k) a.mutable_data()[k] = v[k];
  return std::move(a);
}

}  // namespace

// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
void bind_character(py::module_& m) {
  py::class_<CharacterOptions>(m, "CharacterOptions", "Options of a Character (see character.hpp).")
      .def(py::init<>())
      .def_readwrite("frames_per_step", &CharacterOptions::frames_per_step)
      .def_readwrite("poses", &CharacterOptions::poses)
      .def_readwrite("inertialization_halflife", &CharacterOptions::inertialization_halflife)
      .def_readwrite("ik", &CharacterOptions::ik)
      .def_readwrite("foot_locking", &CharacterOptions::foot_locking)
      .def_readwrite("ik_margin", &CharacterOptions::ik_margin)
      .def_readwrite("lock_release_distance", &CharacterOptions::lock_release_distance)
      .def_readwrite("lock_blend_time", &CharacterOptions::lock_blend_time);

  py::class_<DatabaseDecider>(m, "Decider",
                              "One database character's decisions (decider.hpp's Decider over the database source, "
                              "with a transition cost and the registered candidate rules: clip costs, the foot-jump "
                              "limit): what mmrl.Character.step decides with.")
      .def(py::init([](const Database& db, PyMatcher& matcher, float action_limit_std, float transition_cost,
                       std::vector<float> clip_costs, float foot_jump_limit) {
             TaskConfig c;
             c.action_limit_std = action_limit_std;
             c.transition_cost = transition_cost;
             c.clip_costs = std::move(clip_costs);
             c.foot_jump_limit = foot_jump_limit;
             return new DatabaseDecider(db, matcher.matcher, c);
           }),
           py::arg("db"), py::arg("matcher"), py::arg("action_limit_std") = 3.0f, py::arg("transition_cost") = 0.0f,
           py::arg("clip_costs") = std::vector<float>{}, py::arg("foot_jump_limit") = 0.0f, py::keep_alive<1, 2>(),
           py::keep_alive<1, 3>())
      .def(
          "decide",
          [](DatabaseDecider& d, int64_t frame, const py::handle& trajectory) {
            auto t = check_array<float>(trajectory, "trajectory_query", {kTrajectoryDim});
            check_finite(t.data(), kTrajectoryDim, "trajectory_query");
            Decision out;
            {
              py::gil_scoped_release release;
              out = d.decide(frame, t.data());
            }
            return py::make_tuple(out.match, out.cost);
          },
          py::arg("frame"), py::arg("trajectory_query"),
          "The decision of a character showing `frame` for a 12-d normalized trajectory: (match, cost).")
      .def_property(
          "transition_cost", &DatabaseDecider::transition_cost,
          [](DatabaseDecider& d, float cost) { d.set_transition_cost(cost); },
          "transition cost of the next decisions (finite, >= 0)");

  py::class_<Character>(m, "Character", "A motion-matching character that plays decisions (C++ core of mmrl.Character).")
      .def(py::init([](const Database& db, const CharacterOptions& options) { return new Character(db, options); }),
           py::arg("db"), py::arg("options"), py::keep_alive<1, 2>())
      .def(
          "reset",
          [](Character& c, int64_t frame, float x, float z, float yaw) {
            if (!std::isfinite(x) || !std::isfinite(z) || !std::isfinite(yaw))
              throw py::value_error("position and yaw must be finite");
            try {
              show_database_frame(c, c.database(), frame, RootState{x, z, yaw});
            } catch (const std::out_of_range&) {
              throw py::index_error("start_frame " + std::to_string(frame) + " is out of range");
            }
          },
          py::arg("frame"), py::arg("x"), py::arg("z"), py::arg("yaw"))
      .def(
          "play",
          [](Character& c, int64_t match, float cost, std::array<float, 2> anchor) {
            check_finite(anchor.data(), 2, "anchor");
            py::gil_scoped_release release;
            play_database_match(c, c.database(), match, cost, anchor.data());
          },
          py::arg("match"), py::arg("cost"), py::arg("anchor") = std::array<float, 2>{0.0f, 0.0f},
          "Plays a database decision (a Decider's, or the env's last_step_match): frames match+1 .. match+F. "
          "anchor: the decision's root move that keeps the planted feet (the env's last_step_anchor).")
      .def(
          "reset_row",
          [](Character& c, const py::handle& row, float x, float z, float yaw) {
            auto r = check_array<float>(row, "row", {pose_row_dim(c.num_joints())});
            check_finite(r.data(), r.size(), "row");
            if (!std::isfinite(x) || !std::isfinite(z) || !std::isfinite(yaw))
              throw py::value_error("position and yaw must be finite");
            show_compressed_row(c, r.data(), RootState{x, z, yaw});
          },
          py::arg("row"), py::arg("x"), py::arg("z"), py::arg("yaw"),
          "A compressed controller's start: shows a pose row (9 J + 5) at the world root.")
      .def(
          "play_rows",
          [](Character& c, const py::handle& rows, bool transition, float cost, std::array<float, 2> anchor) {
            auto r = check_array<float>(rows, "rows", {c.options().frames_per_step + 1, pose_row_dim(c.num_joints())});
            check_finite(r.data(), r.size(), "rows");
            check_finite(anchor.data(), 2, "anchor");
            py::gil_scoped_release release;
            play_compressed_rows(c, r.data(), transition, cost, anchor.data());
          },
          py::arg("rows"), py::arg("transition"), py::arg("cost"), py::arg("anchor") = std::array<float, 2>{0.0f, 0.0f},
          "Plays a compressed controller's decision (the env's compressed_rows): rows 1.. are shown.")
      .def_property_readonly("num_joints", &Character::num_joints)
      .def_property_readonly("frames_per_step", [](const Character& c) { return c.options().frames_per_step; })
      .def_property_readonly("root",
                             [](const Character& c) { return py::make_tuple(c.root().x, c.root().z, c.root().yaw); })
      .def_property_readonly("frame", &Character::frame)
      .def_property_readonly("last_match", &Character::last_match)
      .def_property_readonly("last_transition", &Character::last_transition)
      .def_property_readonly("last_cost", &Character::last_cost)
      .def_property_readonly("played_frames",
                             [](const Character& c) {
                               return py::array_t<int64_t>(c.options().frames_per_step, c.played_frames());
                             })
      .def_property_readonly("roots",
                             [](py::object self) {
                               const Character& c = self.cast<const Character&>();
                               return make_view(c.roots(), {c.options().frames_per_step, 3}, self);
                             })
      .def_property_readonly("contacts",
                             [](py::object self) {
                               const Character& c = self.cast<const Character&>();
                               return make_view(c.contacts(), {c.options().frames_per_step, 2}, self);
                             })
      .def_property_readonly("lock_weights",
                             [](py::object self) {
                               const Character& c = self.cast<const Character&>();
                               return make_view(c.lock_weights(), {c.options().frames_per_step, 2}, self);
                             })
      .def(
          "poses",
          [](py::object self) {
            const Character& c = self.cast<const Character&>();
            if (!c.options().poses) throw py::value_error("the fast path (poses off) produces no poses");
            const py::ssize_t F = c.options().frames_per_step, J = c.num_joints();
            return py::make_tuple(make_view(c.global_positions(), {F, J, 3}, self),
                                  make_view(c.global_rotations(), {F, J, 4}, self),
                                  make_view(c.local_translations(), {F, J, 3}, self),
                                  make_view(c.local_rotations(), {F, J, 4}, self));
          },
          "Views (overwritten by the next step): global positions, global rotations, local translations, "
          "local rotations of the frames played by the last step.")
      .def(
          "animated_feet",
          [](py::object self) {
            const Character& c = self.cast<const Character&>();
            if (!c.options().poses) throw py::value_error("the fast path (poses off) produces no poses");
            return make_view(c.animated_feet(), {c.options().frames_per_step, 2, 3}, self);
          },
          "View (overwritten by the next step), (F, 2, 3) world meters: the left and right ankles of the frames "
          "played by the last step before foot locking and IK, i.e. the ankles of the same run with IK off.")
      .def(
          "current_animated_feet",
          [](py::object self) {
            const Character& c = self.cast<const Character&>();
            if (!c.options().poses) throw py::value_error("the fast path (poses off) produces no poses");
            return make_view(c.current_animated_feet(), {2, 3}, self);
          },
          "View (2, 3): the ankles of the pose shown now before foot locking and IK.")
      .def(
          "current_lock_weights",
          [](py::object self) {
            const Character& c = self.cast<const Character&>();
            return make_view(c.current_lock_weights(), {2}, self);
          },
          "View (2,): the left and right foot lock weights (0..1) of the pose shown now.")
      .def(
          "current_pose",
          [](py::object self) {
            const Character& c = self.cast<const Character&>();
            if (!c.options().poses) throw py::value_error("the fast path (poses off) produces no poses");
            const py::ssize_t J = c.num_joints();
            return py::make_tuple(make_view(c.current_global_positions(), {J, 3}, self),
                                  make_view(c.current_global_rotations(), {J, 4}, self),
                                  make_view(c.current_local_translations(), {J, 3}, self),
                                  make_view(c.current_local_rotations(), {J, 4}, self));
          },
          "Views of the pose shown now.");

  m.def(
      "ik_two_bone",
      [](const py::handle& hip, const py::handle& knee, const py::handle& ankle, const py::handle& target,
         float margin, const py::object& pole) {
        IkTwoBoneJob job;
        job.hip = vec3_arg(hip, "hip");
        job.knee = vec3_arg(knee, "knee");
        job.ankle = vec3_arg(ankle, "ankle");
        job.target = vec3_arg(target, "target");
        job.margin = margin;
        if (!pole.is_none()) {
          job.pole = vec3_arg(pole, "pole");
          job.pole_from_knee = false;
        }
        if (!job.Validate())
          throw py::value_error("ik_two_bone: invalid input (bones must be longer than 1 mm and the margin in "
                                "[0, shorter bone))");
        job.Run();
        py::dict d;
        d["hip_correction"] = quat_array(job.hip_correction);
        d["knee_correction"] = quat_array(job.knee_correction);
        d["knee"] = vec_array(job.new_knee);
        d["ankle"] = vec_array(job.new_ankle);
        d["reached"] = job.reached;
        return d;
      },
      py::arg("hip"), py::arg("knee"), py::arg("ankle"), py::arg("target"), py::arg("margin") = 0.015f,
      py::arg("pole") = py::none(),
      "Analytic two-bone IK (see ik.hpp). Inputs are float32 (3,) arrays in one space, meters.");

  m.def(
      "database_global_positions",
      [](const Database& db, const py::handle& frames) {
        auto f = check_array<int64_t>(frames, "frames", {-1});
        for (py::ssize_t i = 0; i < f.size(); ++i)
          if (f.data()[i] < 0 || f.data()[i] >= db.num_frames) throw py::index_error("frames: index out of range");
        py::array_t<float> out({f.size(), static_cast<py::ssize_t>(db.num_joints), py::ssize_t(3)});
        float* o = out.mutable_data();
        const int64_t* fp = f.data();
        const py::ssize_t n = f.size();
        {
          py::gil_scoped_release release;
          std::vector<float> scratch(static_cast<size_t>(db.num_joints) * 4);
          for (py::ssize_t i = 0; i < n; ++i) database_pose_global(db, fp[i], o + i * db.num_joints * 3, scratch.data());
        }
        return out;
      },
      py::arg("db"), py::arg("frames"), "Global joint positions (M, J, 3) of database frames in the database's world.");

  m.def(
      "motion_from_pose",
      [](const Database& db, const py::handle& translations, const py::handle& rotations, const std::string& source) {
        const py::ssize_t J = db.num_joints;
        auto t = check_array<float>(translations, "local_translations", {-1, J, 3});
        auto r = check_array<float>(rotations, "local_rotations", {t.shape(0), J, 4});
        check_finite(t.data(), t.size(), "local_translations");
        check_finite(r.data(), r.size(), "local_rotations");
        if (t.shape(0) < 1) throw py::value_error("local_translations: need at least one frame");
        Motion mo;
        mo.skeleton = db.skeleton;
        mo.source = source;
        mo.frame_time = 1.0f / db.fps;
        mo.scale = db.source_scale;
        mo.num_frames = static_cast<int>(t.shape(0));
        mo.translations.assign(t.data(), t.data() + t.size());
        mo.rotations.assign(r.data(), r.data() + r.size());
        return mo;
      },
      py::arg("db"), py::arg("local_translations"), py::arg("local_rotations"), py::arg("source") = "<generated>",
      "A Motion on the database's skeleton from local transforms (meters; quaternions w x y z).");
}

}  // namespace mmrl
