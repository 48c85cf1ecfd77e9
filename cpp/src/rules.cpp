#include "mmrl/rules.hpp"

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

std::vector<CandidateRuleType>& registry() {
  // The builtin rules, one line each, in chain order. (The obstacles' path filter is that
  // task's own, on top of the chain: obstacles.hpp.)
  static std::vector<CandidateRuleType> types = {
      {"clip-costs", [](const Database& db, const TaskConfig& c) -> std::unique_ptr<CandidateRule> {
         return c.clip_costs.empty() ? nullptr : std::make_unique<ClipCostRule>(db, c.clip_costs);
       }},
      {"request", [](const Database& db, const TaskConfig&) -> std::unique_ptr<CandidateRule> {
         return std::make_unique<RequestRule>(db);
       }},
  };
  return types;
}

}  // namespace

const std::vector<CandidateRuleType>& candidate_rule_types() { return registry(); }

int register_candidate_rule(CandidateRuleType type) {
  registry().push_back(std::move(type));
  return static_cast<int>(registry().size()) - 1;
}

void unregister_candidate_rules_after(int n) {
  if (n >= 0 && static_cast<size_t>(n) < registry().size()) registry().resize(static_cast<size_t>(n));
}

}  // namespace mmrl
