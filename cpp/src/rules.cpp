#include "mmrl/rules.hpp"

namespace mmrl {

namespace {

std::vector<CandidateRuleType>& registry() {
  // The builtin rules, one line each. (The clip costs and a request's clips are the base of
  // every chain, and the obstacles' path filter is that task's own: vecenv.hpp, obstacles.hpp.)
  static std::vector<CandidateRuleType> types = {};
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
