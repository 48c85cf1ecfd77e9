// The Python object of a compressed controller (bind_compressed.cpp), shared with the env and
// character bindings that play it, and the methods every task env has for it (set_compressed
// and its state's accessors): the compressed source's bindings, in one place.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "bindings.hpp"
#include "mmrl/compressed_source.hpp"

namespace mmrl {

struct PyCompressed {
  CompressedModel model;
  std::vector<float> frame_states;  // num_frame_states x state_dim: each database frame's state
  py::ssize_t num_frame_states = 0;
};

void bind_compressed(py::module_& m);

// The compressed controller wrapper s's env plays, or ValueError naming the method.
template <class Wrapper>
const CompressedSource& compressed_of(const Wrapper& s, const char* method) {
  const auto* source = dynamic_cast<const CompressedSource*>(&s.env.source());
  if (source == nullptr) throw py::value_error(std::string(method) + ": no compressed controller is set");
  return *source;
}

// One of env i's compressed states (a CompressedState buffer of state_dim floats) as a numpy view.
template <class Wrapper>
auto state_view(std::vector<float> CompressedState::*buffer, const char* method) {
  return [buffer, method](const Wrapper& s, int i) {
    const int dim = compressed_of(s, method).state_dim();
    return py::array_t<float>(dim, (CompressedState::of(s.env.motion(checked_env_index(s, i))).*buffer).data());
  };
}

// set_compressed and the compressed state's accessors of a task env's class c.
// long: a binding table, one .def per method; each lambda only converts, checks and forwards.
template <class Wrapper>
void bind_compressed_env(py::class_<Wrapper>& c) {
  c.def(
       "set_compressed",
       [](Wrapper& s, PyCompressed* model) {
         if (model == nullptr) {
           s.env.set_source(nullptr);
           return;
         }
         if (model->num_frame_states != s.env.database().num_frames)
           throw py::value_error("set_compressed: the model has " + std::to_string(model->num_frame_states) +
                                 " frame states, the database " + std::to_string(s.env.database().num_frames) +
                                 " frames");
         s.env.set_source(std::make_shared<CompressedSource>(s.env.database(), model->model, model->frame_states.data()));
       },
       py::arg("model"), py::keep_alive<1, 2>(),
       "Plays a compressed controller (CompressedModel with the database's frame states) instead of the database, "
       "from the next episode start (every env restarts its state from its frame now); None: the database again.")
      .def(
          "compressed_rows",
          [](const Wrapper& s, int i) {
            const CompressedModel& m = compressed_of(s, "compressed_rows").model();
            const py::ssize_t F = s.env.config().frames_per_step + 1, P = m.pose_dim();
            return py::array_t<float>({F, P}, CompressedState::of(s.env.motion(checked_env_index(s, i))).rows.data());
          },
          py::arg("index"), "Env i's last decision's pose rows (frames_per_step + 1, pose_dim): row 0 the chosen state.")
      .def("compressed_state", state_view<Wrapper>(&CompressedState::shown, "compressed_state"), py::arg("index"),
           "Env i's compressed state shown now (state_dim).")
      .def("compressed_played", state_view<Wrapper>(&CompressedState::next, "compressed_played"), py::arg("index"),
           "The state at the end of env i's last playback (kept through the autoreset).")
      .def("compressed_chosen", state_view<Wrapper>(&CompressedState::chosen, "compressed_chosen"), py::arg("index"),
           "The state env i's last decision chose (the projection or the continuation; state_dim).")
      .def(
          "set_compressed_state",
          [](Wrapper& s, int i, const py::handle& state) {
            auto a = check_array<float>(state, "state", {compressed_of(s, "set_compressed_state").state_dim()});
            s.env.set_motion_state(checked_env_index(s, i), a.data());
          },
          py::arg("index"), py::arg("state"), "Sets env i's compressed state (state_dim, finite).");
}

}  // namespace mmrl
