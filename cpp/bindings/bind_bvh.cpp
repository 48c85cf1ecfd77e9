#include "bindings.hpp"

namespace mmrl {
void bind_bvh(py::module_& m) { (void)m; }
}  // namespace mmrl
