// mmrl._core.CompressedModel: a compressed controller's networks (compressed.hpp), built from
// the arrays of a compressed file (python/mmrl/compress/model.py) and the database frames'
// states. Convert, check, forward.
#include "bind_compressed.hpp"

#include <string>

namespace mmrl {

namespace {

Mlp mlp_arg(const py::handle& layers, const char* name) {
  Mlp m;
  for (const py::handle& item : layers) {
    auto pair = py::reinterpret_borrow<py::tuple>(item);
    if (pair.size() != 2) throw py::value_error(std::string(name) + ": expected (weight, bias) pairs");
    auto w = check_array<float>(pair[0], name, {-1, -1});
    auto b = check_array<float>(pair[1], name, {w.shape(0)});
    Mlp::Layer l;
    l.out = static_cast<int>(w.shape(0));
    l.in = static_cast<int>(w.shape(1));
    l.weight.assign(w.data(), w.data() + w.size());
    l.bias.assign(b.data(), b.data() + b.size());
    m.layers.push_back(std::move(l));
  }
  return m;
}

std::vector<float> vector_arg(const py::handle& obj, const char* name) {
  auto a = check_array<float>(obj, name, {-1});
  return std::vector<float>(a.data(), a.data() + a.size());
}

// Rows of a batch (N x dim, float32), checked finite.
carray<float> rows_arg(const py::handle& obj, const char* name, int dim) {
  auto a = check_array<float>(obj, name, {-1, dim});
  check_finite(a.data(), a.size(), name);
  return a;
}

// f over the rows of a batch (N x in_dim, float32, finite) into a new N x out_dim array, GIL released.
template <class F>
py::array_t<float> batch(const PyCompressed& p, const py::handle& rows, const char* name, int in_dim, int out_dim,
                         F&& f) {
  auto a = rows_arg(rows, name, in_dim);
  const py::ssize_t n = a.shape(0);
  py::array_t<float> out({n, static_cast<py::ssize_t>(out_dim)});
  float* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    CompressedScratch scratch = p.model.make_scratch();
    for (py::ssize_t i = 0; i < n; ++i) f(a.data() + i * in_dim, o + i * out_dim, scratch);
  }
  return out;
}

}  // namespace

// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
void bind_compressed(py::module_& m) {
  m.def("mlp_kernel", [] { return std::string(mlp_kernel()); },
        "The compressed networks' dense kernel in this process: 'f16c' (AVX2 and F16C) or 'widening' "
        "(any CPU, the same bits; MMRL_NO_F16C forces it).");
  py::class_<PyCompressed>(m, "CompressedModel", "A compressed controller's networks (compressed.hpp).")
      .def(py::init([](int num_joints, int latent, const py::list& decompressor, const py::list& stepper,
                       const py::list& projector, const py::handle& y_mean, const py::handle& y_std,
                       const py::handle& z_mean, const py::handle& z_std, const py::handle& frame_states,
                       const py::handle& fixed_joints, const py::handle& fixed_translations) {
             auto* p = new PyCompressed();
             CompressedModel& c = p->model;
             c.num_joints = num_joints;
             c.latent = latent;
             c.decompressor = mlp_arg(decompressor, "decompressor");
             c.stepper = mlp_arg(stepper, "stepper");
             c.projector = mlp_arg(projector, "projector");
             c.y_mean = vector_arg(y_mean, "y_mean");
             c.y_std = vector_arg(y_std, "y_std");
             c.z_mean = vector_arg(z_mean, "z_mean");
             c.z_std = vector_arg(z_std, "z_std");
             if (!fixed_joints.is_none()) {
               auto f = check_array<uint8_t>(fixed_joints, "fixed_joints", {num_joints});
               c.fixed_joints.assign(f.data(), f.data() + f.size());
               auto t = check_array<float>(fixed_translations, "fixed_translations", {num_joints, 3});
               c.fixed_translations.assign(t.data(), t.data() + t.size());
             }
             try {
               c.prepare();
             } catch (...) {
               delete p;
               throw;
             }
             if (!frame_states.is_none()) {
               auto s = rows_arg(frame_states, "frame_states", c.state_dim());
               p->frame_states.assign(s.data(), s.data() + s.size());
               p->num_frame_states = s.shape(0);
             }
             return p;
           }),
           py::arg("num_joints"), py::arg("latent"), py::arg("decompressor"), py::arg("stepper"), py::arg("projector"),
           py::arg("y_mean"), py::arg("y_std"), py::arg("z_mean"), py::arg("z_std"), py::arg("frame_states") = py::none(),
           py::arg("fixed_joints") = py::none(), py::arg("fixed_translations") = py::none())
      .def_property_readonly("num_joints", [](const PyCompressed& p) { return p.model.num_joints; })
      .def_property_readonly("latent", [](const PyCompressed& p) { return p.model.latent; })
      .def_property_readonly("pose_dim", [](const PyCompressed& p) { return p.model.pose_dim(); })
      .def_property_readonly("state_dim", [](const PyCompressed& p) { return p.model.state_dim(); })
      .def_property_readonly("num_frame_states", [](const PyCompressed& p) { return p.num_frame_states; })
      .def_property_readonly("num_parameters", [](const PyCompressed& p) { return p.model.num_parameters(); })
      .def_property_readonly("memory_bytes", [](const PyCompressed& p) { return p.model.memory_bytes(); },
                             "Bytes of the networks and normalizations (not the frame states).")
      .def(
          "decode",
          [](const PyCompressed& p, const py::handle& states) {
            return batch(p, states, "states", p.model.state_dim(), p.model.pose_dim(),
                         [&](const float* in, float* out, CompressedScratch& s) { p.model.decode(in, out, s); });
          },
          py::arg("states"), "The pose rows (N, pose_dim) of states (N, state_dim).")
      .def(
          "step",
          [](const PyCompressed& p, const py::handle& states) {
            const int S = p.model.state_dim();
            return batch(p, states, "states", S, S, [&](const float* in, float* out, CompressedScratch& s) {
              std::copy(in, in + S, out);
              p.model.step(out, s);
            });
          },
          py::arg("states"), "Each state (N, state_dim) one frame later.")
      .def(
          "project",
          [](const PyCompressed& p, const py::handle& queries) {
            return batch(p, queries, "queries", kFeatureDim, p.model.state_dim(),
                         [&](const float* in, float* out, CompressedScratch& s) { p.model.project(in, out, s); });
          },
          py::arg("queries"), "The projected states (N, state_dim) of normalized queries (N, 27).")
      .def(
          "decide",
          [](const PyCompressed& p, const py::handle& state, const py::handle& query, float transition_cost) {
            const int S = p.model.state_dim();
            auto s = check_array<float>(state, "state", {S});
            auto q = check_array<float>(query, "query", {kFeatureDim});
            check_finite(s.data(), S, "state");
            check_finite(q.data(), kFeatureDim, "query");
            if (!(transition_cost >= 0) || !std::isfinite(transition_cost))
              throw py::value_error("transition_cost must be finite and >= 0");
            py::array_t<float> chosen(S);
            CompressedScratch scratch = p.model.make_scratch();
            float cost = 0;
            const bool t = compressed_decision(p.model, s.data(), q.data(), transition_cost, chosen.mutable_data(),
                                               &cost, scratch);
            if (!t) std::copy(s.data(), s.data() + S, chosen.mutable_data());
            return py::make_tuple(t, chosen, cost);
          },
          py::arg("state"), py::arg("query"), py::arg("transition_cost"),
          "The compressed decision (compressed_decision): (transition, the chosen state, its cost).")
      .def(
          "playback",
          [](const PyCompressed& p, const py::handle& state, int frames) {
            const int S = p.model.state_dim();
            auto s = check_array<float>(state, "state", {S});
            check_finite(s.data(), S, "state");
            if (frames < 0 || frames > kCompressedMaxFrames)
              throw py::value_error("frames must be in 0.." + std::to_string(kCompressedMaxFrames));
            py::array_t<float> rows({static_cast<py::ssize_t>(frames + 1), static_cast<py::ssize_t>(p.model.pose_dim())});
            py::array_t<float> end(S);
            CompressedScratch scratch = p.model.make_scratch();
            compressed_playback(p.model, s.data(), frames, rows.mutable_data(), end.mutable_data(), scratch);
            return py::make_tuple(rows, end);
          },
          py::arg("state"), py::arg("frames"),
          "compressed_playback: (the pose rows (frames + 1, pose_dim) from the state, the state after them).");
}

}  // namespace mmrl
