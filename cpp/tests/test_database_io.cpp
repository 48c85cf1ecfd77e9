// database_io.hpp: a Database rebuilt from its saved arrays equals the original; every bad
// field is refused with an error naming it.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "env_test_database.hpp"
#include "mmrl/database_io.hpp"

namespace mmrl {
namespace {

template <class T, class Container>
StateArray<T> stored(const Container& v, std::vector<int64_t> shape) {
  return StateArray<T>{std::vector<T>(v.begin(), v.end()), std::move(shape)};
}

// The state a save writes (python/mmrl/motion/database.py saves Database.state()).
DatabaseState state_of(const Database& db) {
  const int64_t N = db.num_frames, J = db.num_joints, C = db.num_clips();
  DatabaseState s;
  s.joint_names = db.skeleton.names;
  s.parents = stored<int32_t>(db.skeleton.parents, {J});
  std::vector<float> off, es;
  for (int j = 0; j < J; ++j)
    for (int k = 0; k < 3; ++k) off.push_back(db.skeleton.offsets[j][k]), es.push_back(db.skeleton.end_sites[j][k]);
  s.offsets = stored<float>(off, {J, 3});
  s.end_sites = stored<float>(es, {J, 3});
  s.has_end_site = stored<uint8_t>(db.skeleton.has_end_site, {J});
  s.channels = skeleton_channels_text(db.skeleton);
  s.roles = joint_roles_as_list(db.roles);
  s.fps = db.fps;
  s.source_scale = db.source_scale;
  s.clip_names = db.clip_names;
  s.clip_ranges = stored<int32_t>(db.clip_ranges, {C, 2});
  s.clip_mirrored = stored<uint8_t>(db.clip_mirrored, {C});
  s.bone_translations = stored<float>(db.bone_translations, {N, J, 3});
  s.bone_rotations = stored<float>(db.bone_rotations, {N, J, 4});
  s.root_positions = stored<float>(db.root_positions, {N, 3});
  s.root_yaws = stored<float>(db.root_yaws, {N});
  s.root_deltas = stored<float>(db.root_deltas, {N, 3});
  s.features = stored<float>(db.features, {N, kFeatureDim});
  s.contacts = stored<uint8_t>(db.contacts, {N, 2});
  s.feature_mean = stored<float>(db.normalization.mean, {kFeatureDim});
  s.block_scale = stored<float>(db.normalization.block_scale, {kNumBlocks});
  s.weights = stored<float>(db.normalization.weights, {kNumBlocks});
  return s;
}

TEST(DatabaseIo, RoundTripGivesTheSameDatabase) {
  const Database& db = testing_db::database();
  const Database back = database_from_state(state_of(db));
  EXPECT_EQ(back.num_frames, db.num_frames);
  EXPECT_EQ(back.skeleton.names, db.skeleton.names);
  EXPECT_EQ(back.skeleton.channels, db.skeleton.channels);
  EXPECT_EQ(joint_roles_as_list(back.roles), joint_roles_as_list(db.roles));
  EXPECT_EQ(back.normalized, db.normalized);  // bit for bit: same features, mean, scales, weights
  EXPECT_EQ(back.valid, db.valid);
  EXPECT_EQ(back.frame_clip, db.frame_clip);
  EXPECT_EQ(back.root_deltas, db.root_deltas);
  EXPECT_EQ(channels_from_text("Xposition Yposition Zposition Zrotation Xrotation Yrotation"),
            (std::vector<Channel>{Channel::Xposition, Channel::Yposition, Channel::Zposition, Channel::Zrotation,
                                  Channel::Xrotation, Channel::Yrotation}));
  EXPECT_TRUE(channels_from_text("").empty());
}

void expect_refused(DatabaseState s, const std::string& word) {
  try {
    database_from_state(std::move(s));
    ADD_FAILURE() << "accepted; expected an error naming " << word;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
  }
}

TEST(DatabaseIo, RefusesBadFieldsNamingThem) {
  const DatabaseState good = state_of(testing_db::database());
  DatabaseState s = good;
  s.features.shape[0] -= 1;
  s.features.values = std::vector<float>(s.features.values.begin(), s.features.values.end() - kFeatureDim);
  expect_refused(s, "'features' has shape");
  s = good;
  s.bone_rotations.shape = {s.bone_rotations.shape[1], s.bone_rotations.shape[0], 4};  // same size, wrong layout
  expect_refused(s, "bone_rotations");
  s = good;
  std::vector<float> w(s.weights.values.begin(), s.weights.values.end());
  w.push_back(1.0f);
  s.weights.values = w;
  expect_refused(s, "weights");  // values disagree with the shape
  s = good;
  s.parents.values.mutable_data()[2] = 5;
  expect_refused(s, "parents");
  s = good;
  s.channels[1] = "Xrotation Wrotation";
  expect_refused(s, "Wrotation");
  s = good;
  s.roles.pop_back();
  expect_refused(s, "roles");
  s = good;
  s.roles[3] = 99;
  expect_refused(s, "role index");
  s = good;
  s.fps = 0;
  expect_refused(s, "fps");
  s = good;
  s.clip_ranges.values.mutable_data()[1] += 1;  // clip 0 overlaps clip 1
  expect_refused(s, "clip_ranges");
  s = good;
  s.features.values.mutable_data()[7] = NAN;
  expect_refused(s, "NaN");
}

}  // namespace
}  // namespace mmrl
