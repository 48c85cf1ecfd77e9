// Tags on clips, and requests that restrict matching to the clips carrying them (issue 26).
//
// A tag is "group=value" (style=elderly, gait=walk): Database::tag_names lists them and
// Database::clip_tags says which clip carries which. A request is a conjunction of terms,
// one per group, each an alternative of values of that group:
//     "style=elderly"   "style=elderly & gait=walk"   "style=elderly|youthful & gait=run"
// The empty request (or "*") selects every clip. A clip satisfies a request when, for every
// term, it carries one of the term's tags.
//
// Every decision path honours a request through one candidate filter (RequestFilter), the
// builtin request rule of every env's rule chain (rules.hpp): the batched envs, the full path
// (which plays the env's decisions), the engine runtime and the viewer. A policy is told the request
// by its code (RequestCode): for each group it is conditioned on, one float per value of the
// group, 1 for the values the request allows there (all 0: the request leaves the group free).
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "mmrl/database.hpp"
#include "mmrl/kdtree.hpp"

namespace mmrl {

// Throws std::invalid_argument unless db's tags are well formed: each name "group=value" with
// both parts non-empty, made of letters, digits and "_-.", names unique, clip_tags C x T of 0/1.
void check_tags(const std::vector<std::string>& tag_names, const std::vector<uint8_t>& clip_tags, int num_clips);

// The groups of db's tags, in order of first appearance, and the tag indices of one group.
std::vector<std::string> tag_groups(const Database& db);
std::vector<int> group_tags(const Database& db, const std::string& group);
// Text listing what db offers: "style: active, elderly, ...; gait: run, walk" ("no tags" when
// untagged). Error messages end with it.
std::string tags_available(const Database& db);

// A parsed request: per term, the indices of the tags it allows (one group per term).
struct TagRequest {
  std::vector<std::vector<int>> terms;
  std::string text;  // canonical text ("" for every clip)
};

// Parses a request against db (std::invalid_argument naming the unknown group or value and
// listing the tags available; a group named twice is an error).
TagRequest parse_request(const Database& db, const std::string& text);

// A request resolved on a database: the clips it allows, and the valid frames of those clips
// (episode starts) kept per clip, O(clips) in memory: a clip's valid frames are one run
// (Database::index_clips), so the k-th start frame is found from per-clip counts. An empty clip
// mask means every clip. Every env (and every runtime character) holds one or more of these.
struct RequestSelection {
  TagRequest request;
  std::vector<uint8_t> clip_mask;          // C, or empty for every clip
  std::vector<int64_t> first_start;        // per allowed clip with valid frames: its first valid frame
  std::vector<int64_t> starts_before{0};   // per such clip, valid frames before it; last: the total
  bool restricts() const { return !clip_mask.empty(); }
  int64_t num_start_frames() const { return starts_before.back(); }
  // The k-th of the valid frames of the allowed clips, ascending (0 <= k < num_start_frames()).
  int64_t start_frame(int64_t k) const;
};

// Resolves a request (std::invalid_argument when it selects no valid frame, listing the tags).
RequestSelection select_request(const Database& db, const TagRequest& request);
RequestSelection select_request(const Database& db, const std::string& text);

// The request rule as a candidate filter: a row whose clip the request does not allow is
// refused, the others cost what the base filter says (the clip costs), or nothing. A candidate
// without a row (a compressed controller's state) has no clip: the rule does not price it.
class RequestFilter final : public CandidateFilter {
 public:
  // mask: C entries (borrowed; null: every clip); base: optional, borrowed.
  void set(const Database& db, const uint8_t* mask, const CandidateFilter* base) {
    frame_clip_ = db.frame_clip.data();
    mask_ = mask;
    base_ = base;
  }
  float extra_cost(const Candidate& c) const override {
    if (c.row < 0) return 0.0f;
    if (mask_ != nullptr && mask_[frame_clip_[c.row]] == 0) return std::numeric_limits<float>::infinity();
    return base_ != nullptr ? base_->extra_cost(c) : 0.0f;
  }
  const CandidateFilter* fallback() const override { return base_; }

 private:
  const int32_t* frame_clip_ = nullptr;
  const uint8_t* mask_ = nullptr;
  const CandidateFilter* base_ = nullptr;
};

// The request code a policy observes: groups it is conditioned on, each with its tags.
class RequestCode {
 public:
  RequestCode() = default;
  // Throws std::invalid_argument for a group db lacks (listing the tags available).
  RequestCode(const Database& db, const std::vector<std::string>& groups);
  int dim() const { return dim_; }
  const std::vector<std::string>& groups() const { return groups_; }
  // Writes dim() floats for a request.
  void encode(const TagRequest& request, float* out) const;

 private:
  std::vector<std::string> groups_;
  std::vector<std::vector<int>> tags_;  // per group, its tag indices (code order)
  int dim_ = 0;
};

// The requests a training env draws per episode: every combination over the code's groups of
// "free" (probability any_probability) or one value (uniform over the rest), weighted by that
// probability; combinations that select no valid frame are left out and the rest renormalized.
struct RequestMix {
  std::vector<RequestSelection> selections;
  std::vector<std::vector<float>> codes;
  std::vector<double> cumulative;  // ascending, last = 1
  bool empty() const { return selections.empty(); }
  // The index for a uniform u in [0, 1).
  size_t pick(double u) const;
};
// Throws std::invalid_argument if any_probability is outside [0, 1] or more than 4096
// combinations arise.
RequestMix request_mix(const Database& db, const RequestCode& code, float any_probability);

}  // namespace mmrl
