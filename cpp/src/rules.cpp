#include "mmrl/rules.hpp"

#include "mmrl/tasks/arrive.hpp"
#include "mmrl/tasks/path_filter.hpp"

#include <algorithm>
#include <limits>

namespace mmrl {

namespace {

// task.clip_costs: each candidate row's clip's cost (a state, no row: 0).
class ClipCostRule final : public CandidateRule {
 public:
  ClipCostRule(const Database& db, const std::vector<float>& costs) : costs_(db, costs) {}

 protected:
  float cost(const Candidate& c) const override { return costs_.extra_cost(c); }

 private:
  ClipCostFilter costs_;  // checks the costs (one per clip, >= 0), naming clip_costs
};

// The env's request (tags.hpp's RequestFilter): refuses rows of the clips outside it; off
// while the request keeps to every clip.
class RequestRule final : public CandidateRule {
 public:
  explicit RequestRule(const Database& db) : db_(db) {}
  bool prepare(const RuleContext& context) override {
    filter_.set(db_, context.request.clip_mask.data(), nullptr);
    return context.request.restricts();
  }

 protected:
  float cost(const Candidate& c) const override { return filter_.extra_cost(c); }

 private:
  const Database& db_;
  RequestFilter filter_;
};

// task.foot_jump_limit: refuses candidates whose left or right foot (features [0:3], [3:6], the
// character frame) is farther than the limit from the shown frame's. The six columns are one
// block with one scale, so the test runs on the normalized features against the limit in those units.
class FootJumpRule final : public CandidateRule {
 public:
  FootJumpRule(const Database& db, float limit) {
    const float units = limit / db.normalization.column_scale()[0];  // features.cpp: the foot_position block
    limit2_ = units * units;
  }
  bool prepare(const RuleContext& context) override {
    const float* f = context.source.current(context.state).features;
    std::copy(f, f + 6, now_);
    return true;
  }

 protected:
  float cost(const Candidate& c) const override {
    for (int foot = 0; foot < 2; ++foot) {
      float d2 = 0;
      for (int j = 3 * foot; j < 3 * foot + 3; ++j) d2 += (c.features[j] - now_[j]) * (c.features[j] - now_[j]);
      if (d2 > limit2_) return std::numeric_limits<float>::infinity();
    }
    return 0.0f;
  }

 private:
  float limit2_ = 0;
  float now_[6] = {};  // the shown frame's normalized foot positions
};

std::vector<CandidateRuleType>& registry() {
  // The builtin rules, one line each, in chain order.
  static std::vector<CandidateRuleType> types = {
      {"clip-costs", [](const RuleSetup& s) -> std::unique_ptr<CandidateRule> {
         return s.config.clip_costs.empty() ? nullptr : std::make_unique<ClipCostRule>(s.db, s.config.clip_costs);
       }},
      {"request", [](const RuleSetup& s) -> std::unique_ptr<CandidateRule> {
         return std::make_unique<RequestRule>(s.db);
       }},
      {"foot-jump", [](const RuleSetup& s) -> std::unique_ptr<CandidateRule> {
         const float limit = s.config.foot_jump_limit;
         return limit > 0 ? std::make_unique<FootJumpRule>(s.db, limit) : nullptr;
       }},
      {"path-filter", make_path_filter_rule},
      {"stand-idle", make_stand_idle_rule},
  };
  return types;
}

}  // namespace

const std::vector<CandidateRuleType>& candidate_rule_types() { return registry(); }

RuleChain::RuleChain(const RuleSetup& setup) {
  for (const CandidateRuleType& type : candidate_rule_types())
    if (auto rule = type.make(setup)) rules_.push_back(std::move(rule));
}

void RuleChain::prepare(const RuleContext& context, DecisionRules& rules) {
  const CandidateFilter* below = nullptr;
  for (const auto& rule : rules_) {
    if (!rule->prepare(context)) continue;
    rule->set_below(below);
    rule->shape(rules);
    below = rule.get();
  }
  rules.filter = below;
}

int register_candidate_rule(CandidateRuleType type) {
  registry().push_back(std::move(type));
  return static_cast<int>(registry().size()) - 1;
}

void unregister_candidate_rules_after(int n) {
  if (n >= 0 && static_cast<size_t>(n) < registry().size()) registry().resize(static_cast<size_t>(n));
}

}  // namespace mmrl
