#include "mmrl/database_source.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "mmrl/character.hpp"

namespace mmrl {

Decision DatabaseSource::decide(MotionState& s, const float* query, const DecisionRules& rules) const {
  Decision d;
  d.match = decision_match(*db_, *matcher_, s.frame, query, &d.cost, rules.transition_cost, rules.filter,
                           rules.shortlist);
  d.transition = d.match != s.frame;
  return d;
}

void DatabaseSource::play(Character& character, const MotionState&, const Decision& d) const {
  play_database_match(character, *db_, d.match, d.cost, d.anchor);
}

void DatabaseSource::show(Character& character, MotionState& s, const RootState& root) const {
  show_database_frame(character, *db_, s.frame, root);
}

void DatabaseFrames::contacts(int k, uint8_t out[2]) const {
  const size_t f = static_cast<size_t>(first_ + k);
  out[0] = db_.contacts[f * 2];
  out[1] = db_.contacts[f * 2 + 1];
}

void DatabaseFrames::velocity_pair(int k, const FramePose&, FramePose& a, FramePose& b) const {
  const int64_t f = first_ + k;
  const int clip = db_.frame_clip[f];
  const bool forward = f + 1 < db_.clip_ranges[clip * 2 + 1];
  const bool backward = f > db_.clip_ranges[clip * 2];
  database_frame_pose(db_, forward || !backward ? f : f - 1, a);
  database_frame_pose(db_, forward ? f + 1 : f, b);
}

void show_database_frame(Character& character, const Database& db, int64_t frame, const RootState& root) {
  if (frame < 0 || frame >= db.num_frames) throw std::out_of_range("start frame out of range");
  character.show(DatabaseFrames(db, frame), root);
}

void play_database_match(Character& character, const Database& db, int64_t match, float cost,
                         const float* anchor) {
  if (match < 0 || match >= db.num_frames || !db.valid[match])
    throw std::invalid_argument("play: frame " + std::to_string(match) + " is not a valid match of the database");
  if (character.frame() < 0)
    throw std::invalid_argument("play: the character shows no database frame (it played a compressed controller's rows)");
  character.play(DatabaseFrames(db, match), match != character.frame(), cost, anchor);
}

DatabaseDecider::DatabaseDecider(const Database& db, const Matcher& matcher, const TaskConfig& config)
    : source_(db, matcher), decider_(db, config.action_limit_std) {
  if (matcher.num_rows() != db.num_frames) throw std::invalid_argument("matcher was not built over this database");
  check_option("foot_jump_limit", config.foot_jump_limit, kNonNegative);
  set_transition_cost(config.transition_cost);
  rules_ = RuleChain(RuleSetup{db, matcher, config});
  every_clip_ = select_request(db, TagRequest{});
}

void DatabaseDecider::set_transition_cost(float cost) {
  if (!(cost >= 0.0f) || !std::isfinite(cost)) throw std::invalid_argument("transition_cost must be finite and >= 0");
  transition_cost_ = cost;
}

Decision DatabaseDecider::decide(int64_t frame, const float* action) {
  if (!source_.starts_at(frame)) throw std::invalid_argument("frame is outside the database");
  source_.start(state_, frame);
  DecisionRules rules;
  rules.transition_cost = transition_cost_;
  rules_.prepare(RuleContext{source_, state_, every_clip_}, rules);
  return decider_.decide(source_, state_, action, rules);
}

}  // namespace mmrl
