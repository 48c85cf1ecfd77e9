// The mmrl._core extension module. Bindings only: convert, check, forward; no logic.
// Each concept registers itself from its own bind_*.cpp file.
#include "bind_compressed.hpp"
#include "bindings.hpp"

PYBIND11_MODULE(_core, m) {
  m.doc() = "mmrl C++ core: BVH, features, matching, controller and batched environments";
  mmrl::bind_bvh(m);
  mmrl::bind_database(m);
  mmrl::bind_search(m);
  mmrl::bind_compressed(m);
  mmrl::bind_character(m);
#define MMRL_TASK(name) mmrl::bind_##name(m);
#include "mmrl/tasks/builtin.hpp"
#undef MMRL_TASK
  mmrl::bind_runtime(m);
}
