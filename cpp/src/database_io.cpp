#include "mmrl/database_io.hpp"

#include <algorithm>
#include <sstream>
#include <stdexcept>

namespace mmrl {

namespace {

// Channel enum order (bvh.hpp).
const char* kChannelNames[6] = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"};

std::string shape_text(const std::vector<int64_t>& shape) {
  std::string t = "(";
  for (size_t i = 0; i < shape.size(); ++i) t += (i ? ", " : "") + std::to_string(shape[i]);
  return t + (shape.size() == 1 ? ",)" : ")");
}

std::invalid_argument state_error(const std::string& message) {
  return std::invalid_argument("database state: " + message);
}

// Takes the values of a stored array after checking its shape (borrowed values stay borrowed).
template <class T>
Buffer<T> take(StateArray<T>& a, const char* name, std::vector<int64_t> shape) {
  int64_t size = 1;
  for (int64_t s : shape) size *= s;
  if (a.shape != shape || static_cast<int64_t>(a.values.size()) != size)
    throw state_error(std::string("'") + name + "' has shape " + shape_text(a.shape) + ", expected " +
                      shape_text(shape));
  return std::move(a.values);
}

// The same, copied into a vector (the small arrays a Database keeps as vectors).
template <class T>
std::vector<T> take_vector(StateArray<T>& a, const char* name, std::vector<int64_t> shape) {
  const Buffer<T> b = take(a, name, std::move(shape));
  return std::vector<T>(b.begin(), b.end());
}

// Adopts given normalized features after checking them against the normalization, row block
// by row block (no N x 27 temporary): equal bit for bit, or std::invalid_argument.
void adopt_normalized(Database& db, StateArray<float>& given) {
  Buffer<float> values = take(given, "normalized", {db.num_frames, kFeatureDim});
  constexpr int kRows = 1024;
  float block[kRows * kFeatureDim];
  for (int r0 = 0; r0 < db.num_frames; r0 += kRows) {
    const int rows = std::min(kRows, db.num_frames - r0);
    features_normalize(db.normalization, db.features.data() + static_cast<size_t>(r0) * kFeatureDim, rows, block);
    if (!std::equal(block, block + rows * kFeatureDim, values.data() + static_cast<size_t>(r0) * kFeatureDim))
      throw state_error("'normalized' disagrees with the features and their normalization");
  }
  db.normalized = std::move(values);
}

}  // namespace

std::vector<std::string> skeleton_channels_text(const Skeleton& skeleton) {
  std::vector<std::string> out;
  for (const auto& ch : skeleton.channels) {
    std::string t;
    for (Channel c : ch) t += (t.empty() ? "" : " ") + std::string(kChannelNames[static_cast<int>(c)]);
    out.push_back(t);
  }
  return out;
}

std::vector<Channel> channels_from_text(const std::string& text) {
  std::vector<Channel> ch;
  std::istringstream is(text);
  std::string t;
  while (is >> t) {
    int k = 0;
    while (k < 6 && t != kChannelNames[k]) ++k;
    if (k == 6) throw state_error("unknown channel '" + t + "'");
    ch.push_back(static_cast<Channel>(k));
  }
  return ch;
}

Database database_from_state(DatabaseState s) {
  Database db;
  const int64_t J = static_cast<int64_t>(s.joint_names.size());
  db.skeleton.names = s.joint_names;
  auto parents = take_vector(s.parents, "parents", {J});
  db.skeleton.parents.assign(parents.begin(), parents.end());
  for (int64_t j = 0; j < J; ++j)
    if (db.skeleton.parents[j] >= j || db.skeleton.parents[j] < -1)
      throw state_error("parents must precede their children");
  const auto off = take_vector(s.offsets, "offsets", {J, 3});
  const auto es = take_vector(s.end_sites, "end_sites", {J, 3});
  db.skeleton.has_end_site = take_vector(s.has_end_site, "has_end_site", {J});
  if (static_cast<int64_t>(s.channels.size()) != J) throw state_error("channels size mismatch");
  for (int64_t j = 0; j < J; ++j) {
    db.skeleton.offsets.emplace_back(off[j * 3], off[j * 3 + 1], off[j * 3 + 2]);
    db.skeleton.end_sites.emplace_back(es[j * 3], es[j * 3 + 1], es[j * 3 + 2]);
    db.skeleton.channels.push_back(channels_from_text(s.channels[j]));
  }
  // Role layout: hips, then per side (left, right) upper leg, lower leg, foot, toe.
  if (s.roles.size() != 9) throw state_error("roles must have 9 entries");
  for (int r : s.roles)
    if (r < 0 || r >= J) throw state_error("role index out of range");
  db.roles.hips = s.roles[0];
  for (int side = 0; side < 2; ++side) {
    db.roles.upper_leg[side] = s.roles[1 + side * 4];
    db.roles.lower_leg[side] = s.roles[2 + side * 4];
    db.roles.foot[side] = s.roles[3 + side * 4];
    db.roles.toe[side] = s.roles[4 + side * 4];
  }
  db.num_joints = static_cast<int>(J);
  db.fps = s.fps;
  db.source_scale = s.source_scale;
  if (!(db.fps > 0)) throw state_error("fps must be positive");
  db.clip_names = s.clip_names;
  const int64_t C = static_cast<int64_t>(db.clip_names.size());
  db.clip_ranges = take_vector(s.clip_ranges, "clip_ranges", {C, 2});
  db.clip_mirrored = take_vector(s.clip_mirrored, "clip_mirrored", {C});
  db.tag_names = s.tag_names;
  if (!db.tag_names.empty() || !s.clip_tags.shape.empty())
    db.clip_tags = take_vector(s.clip_tags, "clip_tags", {C, static_cast<int64_t>(db.tag_names.size())});
  const int64_t N = C > 0 ? db.clip_ranges[C * 2 - 1] : 0;
  if (N < 0) throw state_error("clip_ranges must not be negative");
  db.num_frames = static_cast<int>(N);
  db.bone_translations = take(s.bone_translations, "bone_translations", {N, J, 3});
  db.bone_rotations = take(s.bone_rotations, "bone_rotations", {N, J, 4});
  db.root_positions = take(s.root_positions, "root_positions", {N, 3});
  db.root_yaws = take(s.root_yaws, "root_yaws", {N});
  db.root_deltas = take(s.root_deltas, "root_deltas", {N, 3});
  db.features = take(s.features, "features", {N, kFeatureDim});
  db.contacts = take_vector(s.contacts, "contacts", {N, 2});
  const auto mean = take(s.feature_mean, "feature_mean", {kFeatureDim});
  const auto bs = take(s.block_scale, "block_scale", {kNumBlocks});
  const auto w = take(s.weights, "weights", {kNumBlocks});
  std::copy(mean.begin(), mean.end(), db.normalization.mean.begin());
  std::copy(bs.begin(), bs.end(), db.normalization.block_scale.begin());
  db.validate();
  db.index_clips();
  std::array<float, kNumBlocks> weights{};
  std::copy(w.begin(), w.end(), weights.begin());
  if (s.normalized.shape.empty()) {
    db.set_weights(weights);
  } else {
    db.check_weights(weights);
    db.normalization.weights = weights;
    adopt_normalized(db, s.normalized);
  }
  return db;
}

}  // namespace mmrl
