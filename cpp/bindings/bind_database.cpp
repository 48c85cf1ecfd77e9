#include "bindings.hpp"

namespace mmrl {
void bind_database(py::module_& m) { (void)m; }
}  // namespace mmrl
