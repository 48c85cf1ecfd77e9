// Deprecated: the decision rule is mmrl/decision.hpp (controller_* are decision_*). "Controller"
// now names only an exported controller (runtime.hpp's RuntimeController). Kept for one release.
#pragma once

#include "mmrl/decision.hpp"
