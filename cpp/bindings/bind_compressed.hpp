// The Python object of a compressed controller (bind_compressed.cpp), shared with the env and
// character bindings that play it.
#pragma once

#include <vector>

#include "bindings.hpp"
#include "mmrl/compressed.hpp"

namespace mmrl {

struct PyCompressed {
  CompressedModel model;
  std::vector<float> frame_states;  // num_frame_states x state_dim: each database frame's state
  py::ssize_t num_frame_states = 0;
};

void bind_compressed(py::module_& m);

}  // namespace mmrl
