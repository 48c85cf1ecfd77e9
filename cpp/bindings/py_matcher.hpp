// The Python-side Matcher object, shared by the search and environment bindings: the
// Matcher borrows the rows and the mask, so the numpy arrays live alongside it.
#pragma once

#include <memory>

#include "bindings.hpp"
#include "mmrl/search.hpp"
#include "mmrl/threadpool.hpp"

namespace mmrl {

struct PyMatcher {
  carray<float> points;
  py::array valid;  // uint8 or bool, borrowed by the Matcher's brute-force path
  Matcher matcher;
  std::unique_ptr<ThreadPool> pool;
};

}  // namespace mmrl
