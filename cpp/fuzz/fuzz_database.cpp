// libFuzzer target: the database loader's rules (database_from_state: every shape against
// N, J and C, the hierarchy, channels, roles, clip ranges, NaN checks, then the derived valid
// mask, clip index and normalized features), fed with arrays of any shape and any values.
//
// The .npz container itself is numpy's (python/mmrl/motion/database.py reads it with
// allow_pickle=False, tests/fuzz/fuzz_python.py fuzzes that path with atheris); this target
// takes the arrays as they come out of it, in a plain encoding (tests/fuzz/make_corpus.py
// writes the seeds from real databases):
//   text list:  u16 count, then per string u16 length + bytes
//   array:      u8 ndim (<= 4), ndim x u32 dims, then the values (little-endian, C order)
//   scalar:     f32
// in the order of DatabaseState's fields. Input that ends early is ignored.
//
// Bad arrays must throw std::invalid_argument; anything else escaping, a crash, a leak or a
// sanitizer report is a finding. A database that loads is also searched once.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "mmrl/database_io.hpp"
#include "mmrl/search.hpp"

namespace {

struct Reader {
  const uint8_t* p;
  size_t left;
  bool ok = true;

  bool take(void* out, size_t n) {
    if (!ok || n > left) return ok = false;
    if (n) std::memcpy(out, p, n);
    p += n;
    left -= n;
    return true;
  }
  template <class T>
  T scalar() {
    T v{};
    take(&v, sizeof(T));
    return v;
  }
  std::vector<std::string> texts() {
    const uint16_t count = scalar<uint16_t>();
    std::vector<std::string> out;
    for (uint16_t k = 0; ok && k < count; ++k) {
      const uint16_t len = scalar<uint16_t>();
      std::string s(ok && len <= left ? len : 0, '\0');
      if (take(s.data(), len)) out.push_back(std::move(s));
    }
    return out;
  }
  template <class T>
  mmrl::StateArray<T> array() {
    mmrl::StateArray<T> a;
    const uint8_t ndim = scalar<uint8_t>();
    if (ndim > 4) ok = false;
    uint64_t count = 1;
    for (uint8_t d = 0; ok && d < ndim; ++d) {
      const uint32_t dim = scalar<uint32_t>();
      a.shape.push_back(dim);
      count *= dim;
      if (count * sizeof(T) > left) ok = false;  // never allocate more than the input holds
    }
    if (!ok) return a;
    std::vector<T> values(count);
    take(values.data(), count * sizeof(T));
    a.values = std::move(values);
    return a;
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader r{data, size};
  mmrl::DatabaseState s;
  s.joint_names = r.texts();
  s.parents = r.array<int32_t>();
  s.offsets = r.array<float>();
  s.end_sites = r.array<float>();
  s.has_end_site = r.array<uint8_t>();
  s.channels = r.texts();
  const auto roles = r.array<int32_t>();
  s.roles.assign(roles.values.begin(), roles.values.end());
  s.fps = r.scalar<float>();
  s.source_scale = r.scalar<float>();
  s.clip_names = r.texts();
  s.clip_ranges = r.array<int32_t>();
  s.clip_mirrored = r.array<uint8_t>();
  s.bone_translations = r.array<float>();
  s.bone_rotations = r.array<float>();
  s.root_positions = r.array<float>();
  s.root_yaws = r.array<float>();
  s.root_deltas = r.array<float>();
  s.features = r.array<float>();
  s.contacts = r.array<uint8_t>();
  s.feature_mean = r.array<float>();
  s.block_scale = r.array<float>();
  s.weights = r.array<float>();
  if (!r.ok) return 0;
  mmrl::Database db;
  try {
    db = mmrl::database_from_state(std::move(s));
  } catch (const std::invalid_argument&) {
    return 0;
  }
  // A loaded database is consistent: the derived arrays have their sizes, and the search tree
  // over it answers its first frame's features as brute force does (index and cost).
  const size_t n = static_cast<size_t>(db.num_frames);
  if (db.valid.size() != n || db.frame_clip.size() != n || db.normalized.size() != n * mmrl::kFeatureDim)
    __builtin_trap();
  if (n == 0) return 0;
  const float* rows = db.normalized.data();
  const mmrl::Matcher matcher(rows, db.num_frames, mmrl::kFeatureDim, db.valid.data());
  float cost = 0, brute_cost = 0;
  const int64_t hit = matcher.match(rows, 0, 0, -1, &cost);
  const int64_t brute = mmrl::brute_force_match(rows, db.num_frames, mmrl::kFeatureDim, db.valid.data(), rows, 0, 0,
                                                -1, &brute_cost);
  if (hit != brute || (hit >= 0 && cost != brute_cost)) __builtin_trap();
  return 0;
}
