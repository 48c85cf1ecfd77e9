#include "bindings.hpp"
#include "mmrl/decision.hpp"
#include "mmrl/database.hpp"
#include "mmrl/database_io.hpp"
#include "mmrl/tags.hpp"

namespace mmrl {

namespace {

std::array<float, kNumBlocks> weights_from(const std::vector<float>& w) {
  if (w.size() != kNumBlocks) throw py::value_error("weights: expected 5 block weights, got " + std::to_string(w.size()));
  std::array<float, kNumBlocks> a{};
  for (int i = 0; i < kNumBlocks; ++i) a[i] = w[i];
  return a;
}

// The dict entry `key` as a stored array: a C-contiguous numpy array of dtype T, copied with
// its shape (database_from_state checks the shapes), or borrowed: the Buffer then points into
// the numpy array's memory and keeps a reference to it (released with the GIL held).
template <class T>
StateArray<T> take(const py::dict& s, const char* key, bool borrow = false) {
  if (!s.contains(key)) throw py::value_error(std::string("database state: missing '") + key + "'");
  const py::handle obj = s[key];
  if (!py::isinstance<py::array>(obj))
    throw py::type_error(std::string(key) + ": expected a numpy array, got " +
                         std::string(py::str(py::type::of(obj).attr("__name__"))));
  auto arr = py::reinterpret_borrow<py::array>(obj);
  if (!has_dtype<T>(arr))
    throw py::type_error(std::string(key) + ": expected dtype " + std::string(py::str(py::dtype::of<T>())) +
                         ", got " + std::string(py::str(arr.dtype())));
  if (!(arr.flags() & py::array::c_style))
    throw py::value_error(std::string(key) + ": array must be C-contiguous (use np.ascontiguousarray)");
  const T* data = static_cast<const T*>(arr.data());
  std::vector<int64_t> shape(arr.shape(), arr.shape() + arr.ndim());
  if (!borrow) return StateArray<T>{std::vector<T>(data, data + arr.size()), std::move(shape)};
  std::shared_ptr<const void> owner(new py::object(arr), [](const void* p) {
    py::gil_scoped_acquire gil;
    delete static_cast<const py::object*>(p);
  });
  return StateArray<T>{Buffer<T>::borrow(data, static_cast<size_t>(arr.size()), std::move(owner)), std::move(shape)};
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
  s["channels"] = skeleton_channels_text(db.skeleton);
  s["roles"] = joint_roles_as_list(db.roles);
  s["fps"] = db.fps;
  s["source_scale"] = db.source_scale;
  s["clip_ranges"] = make_view(db.clip_ranges.data(), {C, 2}, self);
  s["clip_names"] = db.clip_names;
  s["clip_mirrored"] = make_view(db.clip_mirrored.data(), {C}, self);
  s["tag_names"] = db.tag_names;
  s["clip_tags"] = make_view(db.clip_tags.data(), {C, static_cast<py::ssize_t>(db.tag_names.size())}, self);
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

// Converts the dict to a DatabaseState and forwards (the checks and rules: database_io.hpp).
// borrow: the large per-frame float arrays (and "normalized", if given) are borrowed, not copied.
Database database_from_dict(const py::dict& s, bool borrow) {
  DatabaseState st;
  st.joint_names = s["joint_names"].cast<std::vector<std::string>>();
  st.parents = take<int32_t>(s, "parents");
  st.offsets = take<float>(s, "offsets");
  st.end_sites = take<float>(s, "end_sites");
  st.has_end_site = take<uint8_t>(s, "has_end_site");
  st.channels = s["channels"].cast<std::vector<std::string>>();
  st.roles = s["roles"].cast<std::vector<int>>();
  st.fps = s["fps"].cast<float>();
  st.source_scale = s["source_scale"].cast<float>();
  st.clip_names = s["clip_names"].cast<std::vector<std::string>>();
  st.clip_ranges = take<int32_t>(s, "clip_ranges");
  st.clip_mirrored = take<uint8_t>(s, "clip_mirrored");
  if (s.contains("tag_names")) st.tag_names = s["tag_names"].cast<std::vector<std::string>>();
  if (s.contains("clip_tags")) st.clip_tags = take<uint8_t>(s, "clip_tags");
  st.bone_translations = take<float>(s, "bone_translations", borrow);
  st.bone_rotations = take<float>(s, "bone_rotations", borrow);
  st.root_positions = take<float>(s, "root_positions", borrow);
  st.root_yaws = take<float>(s, "root_yaws", borrow);
  st.root_deltas = take<float>(s, "root_deltas", borrow);
  st.features = take<float>(s, "features", borrow);
  st.contacts = take<uint8_t>(s, "contacts");
  st.feature_mean = take<float>(s, "feature_mean");
  st.block_scale = take<float>(s, "block_scale");
  st.weights = take<float>(s, "weights");
  if (s.contains("normalized")) st.normalized = take<float>(s, "normalized", borrow);
  py::gil_scoped_release release;  // the checks read every frame
  return database_from_state(std::move(st));
}

// Names of the per-frame arrays db borrows (Buffer::borrowed) instead of owning.
std::vector<std::string> borrowed_array_names(const Database& db) {
  std::vector<std::string> names;
  const std::pair<const char*, const Buffer<float>*> arrays[] = {
      {"bone_translations", &db.bone_translations}, {"bone_rotations", &db.bone_rotations},
      {"root_positions", &db.root_positions},       {"root_yaws", &db.root_yaws},
      {"root_deltas", &db.root_deltas},             {"features", &db.features},
      {"normalized", &db.normalized}};
  for (const auto& [name, buffer] : arrays)
    if (buffer->borrowed()) names.emplace_back(name);
  return names;
}

}  // namespace

// The feature layout and the constants Python needs, from the C++ that defines them
// (features.hpp, decision.hpp).
void bind_layout_constants(py::module_& m) {
  m.attr("FEATURE_DIM") = kFeatureDim;
  m.attr("POSE_DIM") = kPoseDim;
  m.attr("TRAJECTORY_DIM") = kTrajectoryDim;
  py::list blocks;
  for (const auto& b : feature_blocks()) {
    std::vector<int> cols(b.columns.begin(), b.columns.begin() + b.size);
    blocks.append(py::make_tuple(b.name, cols, b.default_weight));
  }
  m.attr("FEATURE_BLOCKS") = blocks;
  py::list offsets, positions, directions;
  for (int k = 0; k < 3; ++k) {
    offsets.append(kTrajectoryOffsets[k]);
    positions.append(trajectory_position_column(k));
    directions.append(trajectory_direction_column(k));
  }
  m.attr("TRAJECTORY_OFFSETS") = py::tuple(offsets);               // frames ahead of the three samples
  m.attr("TRAJECTORY_POSITION_COLUMNS") = py::tuple(positions);    // x column of each sample's position (z next)
  m.attr("TRAJECTORY_DIRECTION_COLUMNS") = py::tuple(directions);  // x column of each sample's direction (z next)
  py::list path_frames;
  for (int s = 0; s < kPathSamples; ++s) path_frames.append(kPathSampleFrames[s]);
  m.attr("PATH_SAMPLE_FRAMES") = py::tuple(path_frames);  // frames ahead of Database::path_samples
  m.attr("IDLE_METERS") = kIdleMeters;  // a frame whose +30-frame sample is nearer stands (features.hpp)
  m.attr("MATCH_EXCLUDE_WINDOW") = kMatchExcludeWindow;
  m.attr("MAX_FRAMES_PER_STEP") = kMaxFramesPerStep;
}

// The tags of a database (tags.hpp): its properties, set_tags, and the request functions.
void bind_tags(py::module_& m, py::class_<Database>& c) {
  c.def_property_readonly("tag_names", [](const Database& db) { return db.tag_names; })
      .def_property_readonly("clip_tags",
                             [](py::object self) {
                               const Database& db = self.cast<const Database&>();
                               return make_view(db.clip_tags.data(),
                                                {db.num_clips(), static_cast<int>(db.tag_names.size())}, self);
                             })
      .def(
          "set_tags",
          [](Database& db, const std::vector<std::string>& names, const py::array& tags) {
            StateArray<uint8_t> a = take<uint8_t>(py::dict(py::arg("clip_tags") = tags), "clip_tags");
            const std::vector<int64_t> want = {db.num_clips(), static_cast<int64_t>(names.size())};
            if (a.shape != want)
              throw py::value_error("clip_tags: expected shape (" + std::to_string(want[0]) + ", " +
                                    std::to_string(want[1]) + ")");
            std::vector<uint8_t> values(a.values.begin(), a.values.end());
            check_tags(names, values, db.num_clips());
            db.tag_names = names;
            db.clip_tags = std::move(values);
          },
          py::arg("names"), py::arg("clip_tags"),
          "Sets the tags (names 'group=value', a (C, T) uint8 0/1 matrix); only on a database nothing uses yet.");;
  m.def(
      "parse_request",
      [](const Database& db, const std::string& text) { return parse_request(db, text).text; }, py::arg("db"),
      py::arg("request"), "The canonical text of a tag request (ValueError naming what is unknown).");
  m.def(
      "select_request",
      [](const Database& db, const std::string& text) {
        const RequestSelection s = select_request(db, text);
        py::array_t<uint8_t> mask(db.num_clips());
        for (int c = 0; c < db.num_clips(); ++c) mask.mutable_at(c) = s.restricts() ? s.clip_mask[c] : 1;
        py::array_t<int64_t> starts(s.num_start_frames());
        for (int64_t k = 0; k < s.num_start_frames(); ++k) starts.mutable_at(k) = s.start_frame(k);
        return py::make_tuple(s.request.text, mask, starts);
      },
      py::arg("db"), py::arg("request"),
      "(canonical text, (C,) uint8 clip mask, valid frames) of a request; ValueError when it selects no valid frame.");
  m.def("tags_available", &tags_available, py::arg("db"), "What tags db offers, as the error messages list them.");
}

void bind_database(py::module_& m) {
  py::class_<Database> db_class(m, "Database", "Flat per-frame arrays of a motion database (see mmrl.Database).");
  db_class
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
      .def_static("from_state", &database_from_dict, py::arg("state"), py::arg("borrow") = false,
                  "A database from the arrays of state() (plus, optionally, 'normalized'). borrow=True keeps the "
                  "large per-frame float arrays where they are (read-only memory is fine: they are only read) "
                  "instead of copying them; the database keeps references to them.")
      .def_property_readonly(
          "borrowed_arrays", &borrowed_array_names,
          "Names of the per-frame arrays this database borrows instead of owning.")
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
      .def_property_readonly("path_samples",
                             [](py::object self) {
                               const Database& db = self.cast<const Database&>();
                               return make_view(db.path_samples.data(), {db.num_frames, kPathSamples, 2}, self);
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
  bind_tags(m, db_class);
  bind_layout_constants(m);
}

}  // namespace mmrl
