// Shared helpers for the binding files: numpy checks that refuse rather than convert.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <sstream>
#include <vector>
#include <string>

namespace py = pybind11;

namespace mmrl {

void bind_bvh(py::module_& m);
void bind_database(py::module_& m);
void bind_search(py::module_& m);
void bind_character(py::module_& m);
void bind_runtime(py::module_& m);
#define MMRL_TASK(name) void bind_##name(py::module_& m);
#include "mmrl/tasks/builtin.hpp"
#undef MMRL_TASK

template <class T>
using carray = py::array_t<T, py::array::c_style>;

// True when arr's dtype equals T's (native byte order). Not only the same dtype object: an
// array that crossed a pickle (Ray's object store, multiprocessing) has an equal dtype that
// is another object.
template <class T>
bool has_dtype(const py::array& arr) {
  const py::dtype d = arr.dtype(), want = py::dtype::of<T>();
  if (d.is(want)) return true;  // the usual case, without a Python call
  return want.attr("__eq__")(d).cast<bool>();  // numpy's equality: '<f4' == float32 here, '>f4' not
}

// Checks that obj is a C-contiguous numpy array of dtype T with the given shape
// (-1 = any size in that dimension) and returns it without copying. Raises TypeError /
// ValueError naming the argument otherwise.
template <class T>
carray<T> check_array(const py::handle& obj, const char* name, std::initializer_list<py::ssize_t> shape) {
  if (!py::isinstance<py::array>(obj))
    throw py::type_error(std::string(name) + ": expected a numpy array, got " +
                         std::string(py::str(py::type::of(obj).attr("__name__"))));
  py::array arr = py::reinterpret_borrow<py::array>(obj);
  if (!has_dtype<T>(arr))
    throw py::type_error(std::string(name) + ": expected dtype " + std::string(py::str(py::dtype::of<T>())) +
                         ", got " + std::string(py::str(arr.dtype())));
  if (arr.ndim() != static_cast<py::ssize_t>(shape.size()))
    throw py::value_error(std::string(name) + ": expected " + std::to_string(shape.size()) + " dimensions, got " +
                          std::to_string(arr.ndim()));
  py::ssize_t i = 0;
  for (py::ssize_t s : shape) {
    if (s >= 0 && arr.shape(i) != s)
      throw py::value_error(std::string(name) + ": expected size " + std::to_string(s) + " in dimension " +
                            std::to_string(i) + ", got " + std::to_string(arr.shape(i)));
    ++i;
  }
  if (!(arr.flags() & py::array::c_style))
    throw py::value_error(std::string(name) + ": array must be C-contiguous (use np.ascontiguousarray)");
  return py::reinterpret_borrow<carray<T>>(arr);
}

// A writable, C-contiguous output buffer of dtype T and the given shape (see check_array).
template <class T>
T* writable_buffer(const py::handle& obj, const char* name, std::initializer_list<py::ssize_t> shape) {
  auto a = check_array<T>(obj, name, shape);
  if (!a.writeable()) throw py::value_error(std::string(name) + ": array is read-only");
  return a.mutable_data();
}

// Raises ValueError naming the argument if any value is NaN or infinite.
inline void check_finite(const float* data, py::ssize_t n, const char* name) {
  for (py::ssize_t i = 0; i < n; ++i)
    if (!std::isfinite(data[i]))
      throw py::value_error(std::string(name) + ": contains NaN or inf (at flat index " + std::to_string(i) + ")");
}

}  // namespace mmrl

namespace mmrl {
struct Skeleton;
struct JointRoles;
// A read-only numpy view of C++-owned memory that keeps `owner` alive.
template <class T>
py::array make_view(const T* data, std::vector<py::ssize_t> shape, py::handle owner);
py::array skeleton_offsets(const Skeleton& sk);
py::dict roles_to_dict(const Skeleton& sk, const JointRoles& roles);
// Env index i of wrapper s (an object with an `env` member), or IndexError naming the range.
template <class Wrapper>
int checked_env_index(const Wrapper& s, int i) {
  if (i < 0 || i >= s.env.num_envs())
    throw py::index_error("env index " + std::to_string(i) + " out of range [0, " + std::to_string(s.env.num_envs()) +
                          ")");
  return i;
}

}  // namespace mmrl
