#include "mmrl/vecenv.hpp"

#include <stdexcept>

namespace mmrl {

std::vector<int64_t> target_env_check(const Database& db, const Matcher& matcher, int num_envs, int frames_per_step) {
  if (num_envs < 1) throw std::invalid_argument("num_envs must be >= 1");
  if (frames_per_step < 1 || frames_per_step > kTrajectoryOffsets[2])
    throw std::invalid_argument("frames_per_step must be between 1 and 30");
  if (matcher.num_rows() != db.num_frames) throw std::invalid_argument("matcher was not built over this database");
  std::vector<int64_t> valid_frames;
  for (int64_t i = 0; i < db.num_frames; ++i)
    if (db.valid[i]) valid_frames.push_back(i);
  if (valid_frames.empty())
    throw std::invalid_argument("the database has no valid frames (every clip is shorter than 31 frames)");
  return valid_frames;
}

}  // namespace mmrl
