#include "bindings.hpp"

namespace mmrl {
void bind_search(py::module_& m) { (void)m; }
}  // namespace mmrl
