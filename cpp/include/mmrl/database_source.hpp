// The database as a motion source (decider.hpp): candidates are the database's valid rows,
// matched exactly by the KD-tree (decision.hpp's decision_match, with the continuation rule,
// the exclusion window and the filters' fallback), and playback shows the rows that follow the
// match with their stored root deltas.
#pragma once

#include "mmrl/character.hpp"
#include "mmrl/decider.hpp"
#include "mmrl/rules.hpp"

namespace mmrl {

class DatabaseSource final : public MotionSource {
 public:
  DatabaseSource() = default;
  // db and matcher are borrowed and must outlive the source.
  DatabaseSource(const Database& db, const Matcher& matcher) : db_(&db), matcher_(&matcher) {}

  void prepare(MotionState& s, int) const override { s.own.reset(); }
  bool rowless_candidates() const override { return false; }
  bool starts_at(int64_t frame) const override { return frame >= 0 && frame < db_->num_frames; }
  void start(MotionState& s, int64_t frame) const override { s.frame = frame; }
  Candidate current(const MotionState& s) const override { return row(s.frame); }
  Decision decide(MotionState& s, const float* query, const DecisionRules& rules) const override;
  Candidate chosen(const MotionState&, const Decision& d) const override { return row(d.match); }
  const float* played_delta(const MotionState&, const Decision& d, int k) const override {
    return &db_->root_deltas[static_cast<size_t>(d.match + k) * 3];
  }
  void end_playback(MotionState& s, const Decision& d, int frames_per_step) const override {
    s.frame = d.match + frames_per_step;
  }
  void play(Character& character, const MotionState& s, const Decision& d) const override;
  void show(Character& character, MotionState& s, const RootState& root) const override;

 private:
  Candidate row(int64_t f) const { return Candidate{f, &db_->normalized[static_cast<size_t>(f) * kFeatureDim]}; }
  const Database* db_ = nullptr;
  const Matcher* matcher_ = nullptr;
};

// The database frames j, j+1, ... as a character plays them (character.hpp): frame k is
// database frame j + k; a frame's velocity is the forward difference inside its clip (backward
// at the clip's last frame; none in a clip of one frame).
class DatabaseFrames final : public PlayedFrames {
 public:
  // db is borrowed and must outlive this.
  DatabaseFrames(const Database& db, int64_t first) : db_(db), first_(first) {}
  int64_t frame(int k) const override { return first_ + k; }
  void pose(int k, FramePose& out) const override { database_frame_pose(db_, first_ + k, out); }
  const float* root_delta(int k) const override { return &db_.root_deltas[static_cast<size_t>(first_ + k) * 3]; }
  void contacts(int k, uint8_t out[2]) const override;
  void velocity_pair(int k, const FramePose& before, FramePose& a, FramePose& b) const override;

 private:
  const Database& db_;
  int64_t first_;
};

// Puts a character on database frame `frame` (any frame of db) at the world root
// (std::out_of_range otherwise).
void show_database_frame(Character& character, const Database& db, int64_t frame, const RootState& root);
// Plays the database decision `match` (a Decider's, or an env's): frames match+1 .. match+F, a
// transition unless match is the frame the character shows. std::invalid_argument when match
// is not a valid match frame, or when the character shows no database frame. anchor: the
// decision's (Decision::anchor), or null.
void play_database_match(Character& character, const Database& db, int64_t match, float cost,
                         const float* anchor = nullptr);

// One database character's decisions outside an env (mmrl.Character.step): a Decider over the
// database source with the registered rules (rules.hpp) that `config` turns on, as any env's
// character has them (no request: every clip), and config's transition cost. Only the base
// options a rule or the decision reads count (action_limit_std, transition_cost, clip_costs,
// foot_jump_limit). db and matcher are borrowed.
class DatabaseDecider {
 public:
  // Throws std::invalid_argument for an option out of its range or bad clip costs.
  DatabaseDecider(const Database& db, const Matcher& matcher, const TaskConfig& config);
  // The decision of a character showing database frame `frame` (0..num_frames-1) for a
  // trajectory action (12 normalized floats, finite).
  Decision decide(int64_t frame, const float* action);
  float transition_cost() const { return transition_cost_; }
  void set_transition_cost(float cost);  // finite, >= 0 (std::invalid_argument otherwise)
  const Decider& decider() const { return decider_; }

 private:
  DatabaseSource source_;
  Decider decider_;
  RuleChain rules_;
  RequestSelection every_clip_;
  float transition_cost_ = 0;
  MotionState state_;
};

}  // namespace mmrl
