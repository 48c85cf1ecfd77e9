#include "mmrl/vecenv.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace mmrl {

namespace {

std::string number_text(double v) {
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.7g", v);  // float32 options: 0.6, not 0.600000024
  return buf;
}

}  // namespace

void check_option(const char* name, double value, const OptionRange& r) {
  const bool inf_ok = r.inf_ok && value == kOptionInf;
  const bool ok = (std::isfinite(value) || inf_ok) && (r.lo_open ? value > r.lo : value >= r.lo) && value <= r.hi;
  if (ok) return;
  std::string rule;
  if (r.hi == kOptionInf && r.lo == -kOptionInf)
    rule = "finite";
  else if (r.hi == kOptionInf)
    rule = std::string(r.inf_ok ? "" : "finite and ") + (r.lo_open ? "> " : ">= ") + number_text(r.lo) +
           (r.inf_ok ? " (inf allowed)" : "");
  else
    rule = "in " + std::string(r.lo_open ? "(" : "[") + number_text(r.lo) + ", " + number_text(r.hi) + "]";
  throw std::invalid_argument(std::string(name) + " must be " + rule + ", got " + number_text(value));
}

void check_task_config(const TaskConfig& c) {
  if (!(c.target_half_extent > c.min_target_distance))
    throw std::invalid_argument("target_half_extent must be larger than min_target_distance, got " +
                                number_text(c.target_half_extent) + " <= " + number_text(c.min_target_distance));
}

void target_env_check(const Database& db, const Matcher& matcher, int num_envs, const TaskConfig& config) {
  if (num_envs < 1) throw std::invalid_argument("num_envs must be >= 1");
  check_task_config(config);
  if (matcher.num_rows() != db.num_frames) throw std::invalid_argument("matcher was not built over this database");
  if (db.valid_frames.empty())
    throw std::invalid_argument("the database has no valid frames (every clip is shorter than 31 frames)");
}

}  // namespace mmrl
