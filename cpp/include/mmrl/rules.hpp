// Candidate rules by registration: a rule that changes which frame plays (which candidate a
// decision picks) is one class and one registration, and every decision path of a task honours
// it: the batched envs, the full path and mmrl play (through the env's decide), the engine
// runtime and the C interface (through the env of the task's core), for both motion sources (a rule prices
// a Candidate: a database row, or a compressed controller's state with its features only).
//
// Each env of every task holds one instance of each registered rule that its config turns on
// (CandidateRuleType::make), built once from the config. The builtin rules come first: the clip
// costs (task.clip_costs), then the env's request (its clips only), the foot-jump limit and the
// obstacles' collision-aware search (tasks/path_filter.hpp: a rule that reads the character's
// obstacles from RuleContext and asks for a shortlist) and the arrive task's stand on long idles
// (tasks/arrive.hpp: it prices a decision only while RuleContext::standing). Before each decision the env prepares
// every rule for the character (RuleContext) and chains the ones that price this decision, in
// registration order, each over the ones before it (RuleChain below). The search then prices
// candidates through extra_cost, so a rule only adds cost (>= 0; +inf refuses) and the search
// stays exact under it. When the rule refuses every candidate the decision falls back to the
// rules below it (decision.hpp).
//
// (mmrl.Character.step, a character deciding outside any task, chains the same registered rules
// with every clip as its request: database_source.hpp's DatabaseDecider.)
//
// Adding a rule: a class deriving from CandidateRule (its cost, and prepare if it needs the
// character's state), its option in the task config's table (task_config.hpp) if it has one,
// and one line in rules.cpp's builtin list, or register_candidate_rule (a plug-in, a test). A
// rule that only some task's config has reads it by dynamic_cast of RuleSetup::config.
#pragma once

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "mmrl/decider.hpp"
#include "mmrl/tags.hpp"
#include "mmrl/tasks/task_config.hpp"

namespace mmrl {

struct ObstacleScene;  // tasks/path_filter.hpp

// What a rule is built from: one env's database, its matcher, and its task's config (the task's
// own type: ObstacleTaskConfig, ...).
struct RuleSetup {
  const Database& db;
  const Matcher& matcher;
  const TaskConfig& config;
};

// What a rule may read of the character before a decision.
struct RuleContext {
  const MotionSource& source;
  const MotionState& state;         // the candidate it shows: source.current(state)
  const RequestSelection& request;  // the clips it keeps to now (restricts(): some only)
  const ObstacleScene* obstacles = nullptr;  // the character's obstacles (tasks that have them), or null
  bool standing = false;  // the task asks the character to stand still (the arrive task once arrived)
  float stand_turn = 0;   // standing: the turn left to the facing it stands with (radians, + = left)
};

class CandidateRule : public CandidateFilter {
 public:
  // The rules below this one, or null.
  void set_below(const CandidateFilter* below) { below_ = below; }
  // Before each decision of a character: returns whether this rule prices the decision (false
  // leaves it out of the chain, which then runs as if the rule were off).
  virtual bool prepare(const RuleContext& /*context*/) { return true; }
  // The cost of the rules below, plus this rule's own (refused below: refused).
  float extra_cost(const Candidate& c) const final {
    const float below = below_ ? below_->extra_cost(c) : 0.0f;
    if (!(below < std::numeric_limits<float>::infinity())) return below;
    const float own = cost(c);
    return own > 0.0f || own != own ? below + own : below;  // a negative cost counts as 0; NaN refuses
  }
  const CandidateFilter* fallback() const final { return below_; }
  // How the search shows this rule its candidates when it prices a decision (a costly rule asks
  // for a shortlist, decision.hpp): changes rules.shortlist and rules.projections; by default
  // nothing (the rule runs inside the exact search).
  virtual void shape(DecisionRules& /*rules*/) const {}

 protected:
  // This rule's own cost of candidate c: >= 0 in squared normalized feature distance, +inf
  // (or NaN) refuses it. Called for candidates whose distance alone could still win.
  virtual float cost(const Candidate& c) const = 0;

 private:
  const CandidateFilter* below_ = nullptr;
};

// A registered rule: its name and what builds it for one env (null when the env's config leaves
// it off; std::invalid_argument for a bad config).
struct CandidateRuleType {
  std::string name;
  std::unique_ptr<CandidateRule> (*make)(const RuleSetup& setup) = nullptr;
};

// The registered rules, in chain order (the builtin ones first).
const std::vector<CandidateRuleType>& candidate_rule_types();

// One character's instances of the registered rules its config turns on, built once; before each
// decision prepare() chains the ones that price it, each over the ones before it, and puts the
// top of the chain (null when none does) in rules.filter and their shortlists in rules: what a
// decision runs with. What every env of every task (vecenv.hpp) and a standalone character's
// decider (database_source.hpp) decide with.
class RuleChain {
 public:
  RuleChain() = default;
  explicit RuleChain(const RuleSetup& setup);
  void prepare(const RuleContext& context, DecisionRules& rules);

 private:
  std::vector<std::unique_ptr<CandidateRule>> rules_;
};
// Adds a rule type after the registered ones (before any env that should use it is built; not
// thread-safe against env construction). Returns its index.
int register_candidate_rule(CandidateRuleType type);
// Removes the rule types registered after the first n (tests).
void unregister_candidate_rules_after(int n);

}  // namespace mmrl
