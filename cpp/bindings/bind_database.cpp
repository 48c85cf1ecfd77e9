#include "bindings.hpp"
#include "mmrl/database.hpp"

namespace mmrl {

namespace {

const char* kChannelNames[6] = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"};

std::array<float, kNumBlocks> weights_from(const std::vector<float>& w) {
  if (w.size() != kNumBlocks) throw py::value_error("weights: expected 5 block weights, got " + std::to_string(w.size()));
  std::array<float, kNumBlocks> a{};
  for (int i = 0; i < kNumBlocks; ++i) a[i] = w[i];
  return a;
}

template <class T>
std::vector<T> take(const py::dict& s, const char* key, std::initializer_list<py::ssize_t> shape) {
  if (!s.contains(key)) throw py::value_error(std::string("database state: missing '") + key + "'");
  auto a = check_array<T>(s[key], key, shape);
  return std::vector<T>(a.data(), a.data() + a.size());
}

py::dict database_state(py::object self) {
  const Database& db = self.cast<const Database&>();
  const py::ssize_t N = db.num_frames, J = db.num_joints, C = db.num_clips();
  py::dict s;
  s["joint_names"] = db.skeleton.names;
  s["parents"] = make_view(reinterpret_cast<const int32_t*>(db.skeleton.parents.data()), {J}, self);
  s["offsets"] = skeleton_offsets(db.skeleton);
  s["has_end_site"] = make_view(db.skeleton.has_end_site.data(), {J}, self);
  py::array_t<float> es({J, py::ssize_t(3)});
  for (py::ssize_t j = 0; j < J; ++j)
    for (int k = 0; k < 3; ++k) es.mutable_at(j, k) = db.skeleton.end_sites[j][k];
  s["end_sites"] = es;
  std::vector<std::string> channels;
  for (const auto& ch : db.skeleton.channels) {
    std::string t;
    for (Channel c : ch) t += (t.empty() ? "" : " ") + std::string(kChannelNames[static_cast<int>(c)]);
    channels.push_back(t);
  }
  s["channels"] = channels;
  s["roles"] = joint_roles_as_list(db.roles);
  s["fps"] = db.fps;
  s["source_scale"] = db.source_scale;
  s["clip_ranges"] = make_view(db.clip_ranges.data(), {C, 2}, self);
  s["clip_names"] = db.clip_names;
  s["clip_mirrored"] = make_view(db.clip_mirrored.data(), {C}, self);
  s["bone_translations"] = make_view(db.bone_translations.data(), {N, J, 3}, self);
  s["bone_rotations"] = make_view(db.bone_rotations.data(), {N, J, 4}, self);
  s["root_positions"] = make_view(db.root_positions.data(), {N, 3}, self);
  s["root_yaws"] = make_view(db.root_yaws.data(), {N}, self);
  s["root_deltas"] = make_view(db.root_deltas.data(), {N, 3}, self);
  s["features"] = make_view(db.features.data(), {N, kFeatureDim}, self);
  s["contacts"] = make_view(db.contacts.data(), {N, 2}, self);
  s["feature_mean"] = make_view(db.normalization.mean.data(), {kFeatureDim}, self);
  s["block_scale"] = make_view(db.normalization.block_scale.data(), {kNumBlocks}, self);
  s["weights"] = make_view(db.normalization.weights.data(), {kNumBlocks}, self);
  return s;
}

Database database_from_state(const py::dict& s) {
  Database db;
  auto names = s["joint_names"].cast<std::vector<std::string>>();
  const py::ssize_t J = static_cast<py::ssize_t>(names.size());
  db.skeleton.names = names;
  auto parents = take<int32_t>(s, "parents", {J});
  db.skeleton.parents.assign(parents.begin(), parents.end());
  for (py::ssize_t j = 0; j < J; ++j)
    if (db.skeleton.parents[j] >= j || db.skeleton.parents[j] < -1)
      throw py::value_error("database state: parents must precede their children");
  auto off = take<float>(s, "offsets", {J, 3});
  auto es = take<float>(s, "end_sites", {J, 3});
  db.skeleton.has_end_site = take<uint8_t>(s, "has_end_site", {J});
  auto channels = s["channels"].cast<std::vector<std::string>>();
  if (static_cast<py::ssize_t>(channels.size()) != J) throw py::value_error("database state: channels size mismatch");
  for (py::ssize_t j = 0; j < J; ++j) {
    db.skeleton.offsets.emplace_back(off[j * 3], off[j * 3 + 1], off[j * 3 + 2]);
    db.skeleton.end_sites.emplace_back(es[j * 3], es[j * 3 + 1], es[j * 3 + 2]);
    std::vector<Channel> ch;
    std::istringstream is(channels[j]);
    std::string t;
    while (is >> t) {
      int k = 0;
      while (k < 6 && t != kChannelNames[k]) ++k;
      if (k == 6) throw py::value_error("database state: unknown channel '" + t + "'");
      ch.push_back(static_cast<Channel>(k));
    }
    db.skeleton.channels.push_back(ch);
  }
  auto roles = s["roles"].cast<std::vector<int>>();
  if (roles.size() != 9) throw py::value_error("database state: roles must have 9 entries");
  for (int r : roles)
    if (r < 0 || r >= J) throw py::value_error("database state: role index out of range");
  db.roles.hips = roles[0];
  for (int side = 0; side < 2; ++side) {
    db.roles.upper_leg[side] = roles[1 + side * 4];
    db.roles.lower_leg[side] = roles[2 + side * 4];
    db.roles.foot[side] = roles[3 + side * 4];
    db.roles.toe[side] = roles[4 + side * 4];
  }
  db.num_joints = static_cast<int>(J);
  db.fps = s["fps"].cast<float>();
  db.source_scale = s["source_scale"].cast<float>();
  if (!(db.fps > 0)) throw py::value_error("database state: fps must be positive");
  db.clip_names = s["clip_names"].cast<std::vector<std::string>>();
  const py::ssize_t C = static_cast<py::ssize_t>(db.clip_names.size());
  db.clip_ranges = take<int32_t>(s, "clip_ranges", {C, 2});
  db.clip_mirrored = take<uint8_t>(s, "clip_mirrored", {C});
  const py::ssize_t N = C > 0 ? db.clip_ranges[C * 2 - 1] : 0;
  db.num_frames = static_cast<int>(N);
  db.bone_translations = take<float>(s, "bone_translations", {N, J, 3});
  db.bone_rotations = take<float>(s, "bone_rotations", {N, J, 4});
  db.root_positions = take<float>(s, "root_positions", {N, 3});
  db.root_yaws = take<float>(s, "root_yaws", {N});
  db.root_deltas = take<float>(s, "root_deltas", {N, 3});
  db.features = take<float>(s, "features", {N, kFeatureDim});
  db.contacts = take<uint8_t>(s, "contacts", {N, 2});
  auto mean = take<float>(s, "feature_mean", {kFeatureDim});
  auto bs = take<float>(s, "block_scale", {kNumBlocks});
  std::copy(mean.begin(), mean.end(), db.normalization.mean.begin());
  std::copy(bs.begin(), bs.end(), db.normalization.block_scale.begin());
  db.validate();
  db.index_clips();
  db.set_weights(weights_from(take<float>(s, "weights", {kNumBlocks})));
  return db;
}

}  // namespace

void bind_database(py::module_& m) {
  py::class_<Database>(m, "Database", "Flat per-frame arrays of a motion database (see mmrl.Database).")
      .def_static(
          "build",
          [](const std::vector<const Motion*>& clips, bool mirror, const std::map<std::string, std::string>& roles,
             const std::vector<float>& weights) {
            DatabaseOptions opt;
            opt.mirror = mirror;
            opt.roles = roles;
            opt.weights = weights_from(weights);
            py::gil_scoped_release release;
            return database_build(clips, opt);
          },
          py::arg("clips"), py::arg("mirror") = false, py::arg("roles") = std::map<std::string, std::string>(),
          py::arg("weights") = std::vector<float>{0.75f, 1.0f, 1.0f, 1.0f, 1.5f})
      .def_static("from_state", &database_from_state, py::arg("state"))
      .def("state", &database_state, "All arrays as a dict of read-only views (for saving).")
      .def_readonly("num_frames", &Database::num_frames)
      .def_readonly("num_joints", &Database::num_joints)
      .def_readonly("fps", &Database::fps)
      .def_readonly("source_scale", &Database::source_scale)
      .def_property_readonly("num_clips", &Database::num_clips)
      .def_property_readonly("joint_names", [](const Database& db) { return db.skeleton.names; })
      .def_property_readonly("parents", [](const Database& db) { return db.skeleton.parents; })
      .def_property_readonly("roles", [](const Database& db) { return roles_to_dict(db.skeleton, db.roles); })
      .def_property_readonly("clip_names", [](const Database& db) { return db.clip_names; })
      .def_property_readonly("features",
                             [](py::object self) {
                               const Database& db = self.cast<const Database&>();
                               return make_view(db.features.data(), {db.num_frames, kFeatureDim}, self);
                             })
      .def_property_readonly("normalized_features",
                             [](py::object self) {
                               const Database& db = self.cast<const Database&>();
                               return make_view(db.normalized.data(), {db.num_frames, kFeatureDim}, self);
                             })
      .def_property_readonly("valid_mask",
                             [](py::object self) {
                               const Database& db = self.cast<const Database&>();
                               return make_view(db.valid.data(), {db.num_frames}, self);
                             })
      .def_property_readonly("frame_clip",
                             [](py::object self) {
                               const Database& db = self.cast<const Database&>();
                               return make_view(db.frame_clip.data(), {db.num_frames}, self);
                             })
      .def_property_readonly("contacts",
                             [](py::object self) {
                               const Database& db = self.cast<const Database&>();
                               return make_view(db.contacts.data(), {db.num_frames, 2}, self);
                             })
      .def_property_readonly("feature_scale",
                             [](const Database& db) {
                               const auto s = db.normalization.column_scale();
                               return py::array_t<float>(kFeatureDim, s.data());
                             })
      .def(
          "with_weights",
          [](const Database& db, const std::vector<float>& w) {
            Database out = db;  // a copy: matchers of `db` keep borrowing its rows unchanged
            out.set_weights(weights_from(w));
            return out;
          },
          py::arg("weights"), "A new Database with other block weights (same mean and block scales).");
  m.attr("FEATURE_DIM") = kFeatureDim;
  m.attr("POSE_DIM") = kPoseDim;
  m.attr("TRAJECTORY_DIM") = kTrajectoryDim;
  py::list blocks;
  for (const auto& b : feature_blocks()) {
    std::vector<int> cols(b.columns.begin(), b.columns.begin() + b.size);
    blocks.append(py::make_tuple(b.name, cols, b.default_weight));
  }
  m.attr("FEATURE_BLOCKS") = blocks;
}

}  // namespace mmrl
