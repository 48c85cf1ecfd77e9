// The character plays whatever frames a motion source hands it (character.hpp's PlayedFrames),
// without asking which source: a third source that hands over the database's own frames but
// names no database frame shows, bit for bit, what the database source shows for the same
// decisions; the database's own checks (a valid match, a character showing a database frame)
// are play_database_match's.
#include <gtest/gtest.h>

#include <random>
#include <stdexcept>
#include <vector>

#include "env_test_database.hpp"
#include "mmrl/character.hpp"
#include "mmrl/database_source.hpp"

namespace mmrl {
namespace {

using testing_db::database;
using testing_db::matcher;

// The database's frames, handed over as a source without database frames would hand them.
class Anonymous final : public PlayedFrames {
 public:
  explicit Anonymous(const DatabaseFrames& frames) : frames_(frames) {}
  int64_t frame(int) const override { return -1; }
  void pose(int k, FramePose& out) const override { frames_.pose(k, out); }
  const float* root_delta(int k) const override { return frames_.root_delta(k); }
  void contacts(int k, uint8_t out[2]) const override { frames_.contacts(k, out); }
  void velocity_pair(int k, const FramePose& before, FramePose& a, FramePose& b) const override {
    frames_.velocity_pair(k, before, a, b);
  }

 private:
  const DatabaseFrames& frames_;
};

void expect_same_step(const Character& a, const Character& b, int F, int J, int step) {
  for (int k = 0; k < F * 3; ++k) ASSERT_EQ(a.roots()[k], b.roots()[k]) << "step " << step;
  for (int k = 0; k < F * J * 3; ++k) ASSERT_EQ(a.global_positions()[k], b.global_positions()[k]) << "step " << step;
  for (int k = 0; k < F * J * 3; ++k) ASSERT_EQ(a.local_translations()[k], b.local_translations()[k]) << "step " << step;
  for (int k = 0; k < F * J * 4; ++k) {
    ASSERT_EQ(a.local_rotations()[k], b.local_rotations()[k]) << "step " << step;
    ASSERT_EQ(a.global_rotations()[k], b.global_rotations()[k]) << "step " << step;
  }
  for (int k = 0; k < F * 6; ++k) ASSERT_EQ(a.animated_feet()[k], b.animated_feet()[k]) << "step " << step;
  for (int k = 0; k < F * 2; ++k) {
    ASSERT_EQ(a.contacts()[k], b.contacts()[k]) << "step " << step;
    ASSERT_EQ(a.lock_weights()[k], b.lock_weights()[k]) << "step " << step;
  }
}

TEST(Character, PlaysAnySourcesFramesAlike) {
  const Database& db = database();
  CharacterOptions options;
  Character ours(db, options), other(db, options);
  DatabaseDecider decider(db, matcher(), TaskConfig{});
  int64_t start = -1;
  for (int64_t f = 0; f < db.num_frames && start < 0; ++f)
    if (db.valid[f]) start = f;
  const RootState root{0.5f, -1.0f, 0.3f};
  show_database_frame(ours, db, start, root);
  other.show(Anonymous(DatabaseFrames(db, start)), root);
  EXPECT_EQ(ours.frame(), start);
  EXPECT_EQ(other.frame(), -1);
  const int F = options.frames_per_step, J = db.num_joints;
  std::mt19937 gen(3);
  std::normal_distribution<float> noise(0.0f, 1.5f);
  int transitions = 0;
  for (int t = 0; t < 120; ++t) {
    float action[kTrajectoryDim];
    for (float& a : action) a = noise(gen);
    const Decision d = decider.decide(ours.frame(), action);
    const bool transition = d.match != ours.frame();
    play_database_match(ours, db, d.match, d.cost);
    const DatabaseFrames frames(db, d.match);
    other.play(Anonymous(frames), transition, d.cost);
    ASSERT_EQ(ours.last_transition(), transition);
    transitions += transition;
    expect_same_step(ours, other, F, J, t);
    for (int k = 0; k < F; ++k) {
      EXPECT_EQ(ours.played_frames()[k], d.match + k + 1);
      EXPECT_EQ(other.played_frames()[k], -1);
    }
  }
  EXPECT_GT(transitions, 10);  // the blends ran: the two agree through transitions
  // The database's checks are its own: a character showing no database frame, and a frame that
  // is not a valid match, are refused.
  EXPECT_THROW(play_database_match(other, db, start, 0.0f), std::invalid_argument);  // start is a valid match
  int64_t invalid = -1;
  for (int64_t f = 0; f < db.num_frames && invalid < 0; ++f)
    if (!db.valid[f]) invalid = f;
  ASSERT_GE(invalid, 0);
  EXPECT_THROW(play_database_match(ours, db, invalid, 0.0f), std::invalid_argument);
  EXPECT_THROW(show_database_frame(ours, db, db.num_frames, root), std::out_of_range);
}

}  // namespace
}  // namespace mmrl
