#include "mmrl/database_source.hpp"

#include <cmath>
#include <stdexcept>

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
  character.play(d.match, d.cost);
}

void DatabaseSource::show(Character& character, MotionState& s, const RootState& root) const {
  character.reset(s.frame, root);
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
