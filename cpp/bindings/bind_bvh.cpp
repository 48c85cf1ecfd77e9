#include <cctype>

#include "bindings.hpp"
#include "mmrl/bvh.hpp"
#include "mmrl/database.hpp"
#include "mmrl/motion_import.hpp"
#include "mmrl/skeleton.hpp"

namespace mmrl {

namespace {

PyObject* g_bvh_error = nullptr;
PyObject* g_role_error = nullptr;

// A read-only numpy view of C++-owned memory that keeps `owner` alive.
template <class T>
py::array view(const T* data, std::vector<py::ssize_t> shape, py::handle owner) {
  py::array_t<T> a(shape, data, owner);
  a.attr("setflags")(py::arg("write") = false);
  return std::move(a);
}

// "auto", "y" or "z" (any case) -> UpAxis; anything else is refused, naming the argument.
UpAxis up_axis_from(const std::string& up) {
  std::string u;
  for (char c : up) u += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (u == "auto") return UpAxis::Auto;
  if (u == "y") return UpAxis::Y;
  if (u == "z") return UpAxis::Z;
  throw py::value_error("up: expected 'y', 'z' or 'auto', got '" + up + "'");
}

py::dict plausibility_to_dict(const MotionPlausibility& p) {
  py::dict d;
  d["seconds"] = p.seconds;
  d["height"] = p.height;
  d["horizontal_extent"] = p.horizontal_extent;
  d["vertical_travel"] = p.vertical_travel;
  d["horizontal_path"] = p.horizontal_path;
  d["median_horizontal_speed"] = p.median_horizontal_speed;
  return d;
}

BVHImportOptions import_options(float scale, const std::string& up, float fps) {
  BVHImportOptions opt;
  opt.scale = scale;
  opt.up = up_axis_from(up);
  opt.fps = fps;
  return opt;
}

}  // namespace

template <class T>
py::array make_view(const T* data, std::vector<py::ssize_t> shape, py::handle owner) {
  return view(data, std::move(shape), owner);
}
template py::array make_view<float>(const float*, std::vector<py::ssize_t>, py::handle);
template py::array make_view<int32_t>(const int32_t*, std::vector<py::ssize_t>, py::handle);
template py::array make_view<uint8_t>(const uint8_t*, std::vector<py::ssize_t>, py::handle);

py::array skeleton_offsets(const Skeleton& sk) {
  py::array_t<float> a({static_cast<py::ssize_t>(sk.num_joints()), py::ssize_t(3)});
  auto r = a.mutable_unchecked<2>();
  for (int j = 0; j < sk.num_joints(); ++j)
    for (int k = 0; k < 3; ++k) r(j, k) = sk.offsets[j][k];
  return std::move(a);
}

py::dict roles_to_dict(const Skeleton& sk, const JointRoles& roles) {
  py::dict d;
  const auto names = joint_role_names();
  const auto idx = joint_roles_as_list(roles);
  for (size_t i = 0; i < names.size(); ++i) d[py::str(names[i])] = idx[i] >= 0 ? py::str(sk.names[idx[i]]) : py::str("");
  return d;
}

// Motion: read-only views of the parsed clip, FK, roles, mirroring, resampling, export.
// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
static void bind_motion(py::module_& m) {
  py::class_<Motion>(m, "Motion", "A parsed BVH clip: skeleton and per-frame local transforms (meters).")
      .def_property_readonly("joint_names", [](const Motion& mo) { return mo.skeleton.names; })
      .def_property_readonly("parents", [](const Motion& mo) { return mo.skeleton.parents; })
      .def_property_readonly("offsets", [](const Motion& mo) { return skeleton_offsets(mo.skeleton); })
      .def_property_readonly("fps", &Motion::fps)
      .def_property_readonly("source_fps", [](const Motion& mo) { return mo.source_fps; },
                             "The file's frame rate before any resampling (snapped to an integer within 1e-4).")
      .def_property_readonly("up_axis", [](const Motion& mo) { return mo.source_up == UpAxis::Z ? "z" : "y"; },
                             "The file's up axis: 'y', or 'z' when the world was rotated to Y up at import.")
      .def_property_readonly("frame_time", [](const Motion& mo) { return mo.frame_time; })
      .def_property_readonly("num_frames", [](const Motion& mo) { return mo.num_frames; })
      .def_property_readonly("num_joints", [](const Motion& mo) { return mo.skeleton.num_joints(); })
      .def_property_readonly("scale", [](const Motion& mo) { return mo.scale; })
      .def_property_readonly("source", [](const Motion& mo) { return mo.source; })
      .def_property_readonly("local_translations",
                             [](py::object self) {
                               const Motion& mo = self.cast<const Motion&>();
                               return make_view(mo.translations.data(), {mo.num_frames, mo.skeleton.num_joints(), 3}, self);
                             })
      .def_property_readonly("local_rotations",
                             [](py::object self) {
                               const Motion& mo = self.cast<const Motion&>();
                               return make_view(mo.rotations.data(), {mo.num_frames, mo.skeleton.num_joints(), 4}, self);
                             })
      .def(
          "global_positions",
          [](const Motion& mo) {
            py::array_t<float> out({mo.num_frames, mo.skeleton.num_joints(), 3});
            float* o = out.mutable_data();
            {
              py::gil_scoped_release release;
              motion_forward_kinematics(mo, o, nullptr);
            }
            return out;
          },
          "Global joint positions (frames x joints x 3), meters, Y up.")
      .def(
          "global_rotations",
          [](const Motion& mo) {
            py::array_t<float> out({mo.num_frames, mo.skeleton.num_joints(), 4});
            float* o = out.mutable_data();
            {
              py::gil_scoped_release release;
              motion_forward_kinematics(mo, nullptr, o);
            }
            return out;
          },
          "Global joint rotations (frames x joints x 4) as unit quaternions (w, x, y, z).")
      .def(
          "roles", [](const Motion& mo, const std::map<std::string, std::string>& overrides) {
            return roles_to_dict(mo.skeleton, skeleton_find_roles(mo.skeleton, overrides));
          },
          py::arg("overrides") = std::map<std::string, std::string>(), "Joint roles found by name: role -> joint name.")
      .def(
          "mirrored", [](const Motion& mo) { return motion_mirror(mo, skeleton_mirror_map(mo.skeleton)); },
          "A copy mirrored across the world YZ plane (x -> -x) with left and right joints swapped: the legs by\n"
          "their roles (found by name), the other joints by name. JointRoleError when a joint with a side has\n"
          "no partner.")
      .def(
          "resampled",
          [](const Motion& mo, float fps) {
            py::gil_scoped_release release;
            return motion_resample(mo, fps);
          },
          py::arg("fps"), "A copy at `fps` frames per second: translations linear, rotations slerp.")
      .def(
          "plausibility",
          [](const Motion& mo) {
            MotionPlausibility p;
            {
              py::gil_scoped_release release;
              p = motion_plausibility(mo);
            }
            return plausibility_to_dict(p);
          },
          "Measures of a person moving over a floor (meters, seconds, m/s); see motion_import.hpp.")
      .def("to_bvh", &bvh_write, "BVH text of this motion on its own skeleton, in the file's units.")
      .def("__repr__", [](const Motion& mo) {
        return "<mmrl.Motion '" + mo.source + "': " + std::to_string(mo.num_frames) + " frames, " +
               std::to_string(mo.skeleton.num_joints()) + " joints, " + std::to_string(mo.fps()) + " fps>";
      });

}

void bind_bvh(py::module_& m) {
  g_bvh_error = PyErr_NewExceptionWithDoc(
      "mmrl._core.BVHError", "A malformed BVH file; the message names the file and the line. Attributes: file, line.",
      PyExc_ValueError, nullptr);
  m.add_object("BVHError", py::handle(g_bvh_error));
  g_role_error = PyErr_NewExceptionWithDoc("mmrl._core.JointRoleError",
                                           "Joint roles could not be found (the message names every missing role and lists the "
                                           "skeleton's joints), or a joint with a side has no mirror partner.",
                                           PyExc_ValueError, nullptr);
  m.add_object("JointRoleError", py::handle(g_role_error));
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const BVHError& e) {
      py::object exc = py::reinterpret_borrow<py::object>(g_bvh_error)(e.what());
      exc.attr("file") = e.file();
      exc.attr("line") = e.line();
      PyErr_SetObject(g_bvh_error, exc.ptr());
    } catch (const RoleError& e) {
      PyErr_SetString(g_role_error, e.what());
    }
  });

  bind_motion(m);
  m.def(
      "bvh_load",
      [](const std::string& path, float scale, const std::string& up, float fps) {
        const BVHImportOptions opt = import_options(scale, up, fps);
        py::gil_scoped_release release;
        return bvh_load(path, opt);
      },
      py::arg("path"), py::arg("scale") = 0.0f, py::arg("up") = "auto", py::arg("fps") = 0.0f,
      "Parse a BVH file: scale <= 0 infers it, up 'auto'|'y'|'z', fps <= 0 keeps the file's rate.");
  m.def(
      "bvh_parse",
      [](const std::string& text, const std::string& source, float scale, const std::string& up, float fps) {
        const BVHImportOptions opt = import_options(scale, up, fps);
        py::gil_scoped_release release;
        return bvh_parse(text, source, opt);
      },
      py::arg("text"), py::arg("source") = "<string>", py::arg("scale") = 0.0f, py::arg("up") = "auto",
      py::arg("fps") = 0.0f, "Parse BVH text (see bvh_load).");
  m.def(
      "joint_side",
      [](const std::string& name) {
        std::string base;
        const int s = joint_side(name, &base);
        return py::make_tuple(s, base);
      },
      py::arg("name"));
}

}  // namespace mmrl
