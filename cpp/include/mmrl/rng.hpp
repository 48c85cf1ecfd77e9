// A small, fast, seedable RNG per environment (splitmix64 stream). Each environment's
// stream is derived from (seed, index), so results do not depend on thread scheduling.
#pragma once

#include <cstdint>

namespace mmrl {

inline uint64_t splitmix64(uint64_t& state) {
  uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

struct Rng {
  uint64_t state = 0;
  Rng() = default;
  Rng(uint64_t seed, uint64_t stream) {
    uint64_t s = seed ^ (0xD1B54A32D192ED03ull * (stream + 1));
    state = splitmix64(s);
  }
  uint64_t next() { return splitmix64(state); }
  // Uniform in [0, 1).
  float uniform() { return static_cast<float>(next() >> 40) * (1.0f / 16777216.0f); }
  float uniform(float lo, float hi) { return lo + (hi - lo) * uniform(); }
  // Uniform integer in [0, n).
  uint64_t below(uint64_t n) { return n ? next() % n : 0; }
};

}  // namespace mmrl
