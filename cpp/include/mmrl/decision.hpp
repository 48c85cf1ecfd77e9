// The motion-matching decision and root-motion playback shared by every runtime path.
//
// A character is a world-space root (x, z in meters, yaw in radians) and a current
// database frame: the frame whose pose is shown now. One controller step:
//   1. query = [normalized pose part of the current frame (15), trajectory part (12)];
//   2. match: the nearest valid frame j outside a window of kMatchExcludeWindow frames on
//      either side of the current frame (in its clip). The current frame itself is the
//      starting best when it is a valid match, so playback continues unless another frame
//      is strictly better (the continuation rule), or with a transition cost m > 0 better by
//      more than m (squared normalized distance): the transition cost that keeps a clip
//      playing unless a jump buys a clearly better match. The window stops the search from
//      jumping a few frames back or ahead in the same clip, which can trap a character in
//      a loop of one step's frames;
//      A candidate filter (kdtree.hpp's CandidateFilter: the decision's one extension
//      point) may refuse candidates or add to their cost, the continuation's included; the
//      match is the least filtered cost. With a shortlist of k > 0 (a costly filter, such as
//      the obstacles task's collision-aware path test) the filter re-ranks only the k nearest
//      candidates by plain distance, plus the continuation (search.hpp's
//      brute_force_match_shortlist is the rule). When a filter refuses every candidate the
//      match is made with the filter it was built over (CandidateFilter::fallback: a
//      request's clips under the path test), and at last without any, so a character always
//      has a frame to play;
//   3. playback: frames j+1 .. j+n are shown; the root advances by the database root
//      deltas of frames j .. j+n-1 (each expressed in its own character frame), and the
//      current frame becomes j+n.
// A valid j has j + 30 inside its clip, so playback of n <= 30 frames never leaves the clip.
// The fast path (training) is exactly this; the full path adds poses on top of it.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include "mmrl/database.hpp"
#include "mmrl/search.hpp"

namespace mmrl {

struct RootState {
  float x = 0.0f, z = 0.0f, yaw = 0.0f;
};

// Applies one frame of root motion: delta = (dx, dz, dyaw) in the character frame.
inline void root_advance(RootState& r, const float* delta) {
  const Vec2 w = local_to_world_xz(delta[0], delta[1], r.yaw);
  r.x += w.x();
  r.z += w.y();
  r.yaw = wrap_angle(r.yaw + delta[2]);
}

// Moves the root by a decision's anchor (dx, dz in the character frame; Decision::anchor).
inline void root_shift(RootState& r, const float* shift) {
  if (shift[0] == 0.0f && shift[1] == 0.0f) return;  // none: the root unchanged bit for bit
  const Vec2 w = local_to_world_xz(shift[0], shift[1], r.yaw);
  r.x += w.x();
  r.z += w.y();
}

// Writes the 27-d normalized query for the current frame and a normalized trajectory part.
inline void decision_query(const Database& db, int64_t frame, const float* trajectory, float* query) {
  const float* pose = &db.normalized[static_cast<size_t>(frame) * kFeatureDim];
  for (int k = 0; k < kPoseDim; ++k) query[k] = pose[k];
  for (int k = 0; k < kTrajectoryDim; ++k) query[kPoseDim + k] = trajectory[k];
}

// The most frames one decision may play: a valid match frame j has j + 30 inside its clip
// (the trajectory's last horizon), so playback of up to this many frames never leaves it.
constexpr int kMaxFramesPerStep = kTrajectoryOffsets[2];

// Throws std::invalid_argument unless 1 <= frames_per_step <= kMaxFramesPerStep: the one
// check of this number, for the envs, the Character and the runtime.
void check_frames_per_step(int frames_per_step);

// Frames on either side of the current one (within its clip) that a search skips.
constexpr int kMatchExcludeWindow = 20;

// How a filter's shortlist is drawn (decision_match): the k nearest candidates of the query,
// and with fan > 0 the fan_k nearest of the query with its trajectory turned by +-step,
// +-2 step, ... +-fan step radians about the vertical (positions and directions; the pose part
// stays), so the filter sees turning clips as well; all ranked by distance to the query itself.
// With escapes > 0, the fan_k nearest of each of the first `escapes` escape queries join too:
// the pose shown now with a fixed trajectory (escape_trajectory: stand where the character is,
// step back, left, right at kEscapeSpeed facing ahead, then walk at kEscapeWalkSpeed towards
// 0, +-45, +-90, +-135 and 180 degrees, turning to face the way, then run the same ways at
// twice that speed), so the filter sees ways to
// wait, give way and go round whatever the query asks. Those queries depend only on the frame
// shown, so their nearest frames are found once per database frame (EscapeTable) and a
// decision only reads them. k = 0: no shortlist (the filter runs inside the exact search).
// fan <= kMaxShortlistFan, escapes <= kMaxEscapes, escapes * fan_k <= kMaxExtraRows.
constexpr int kMaxShortlistFan = 4;
constexpr int kMaxEscapes = 20;
constexpr float kEscapeSpeed = 0.5f;      // m/s of standing's neighbours: the step back and the steps aside
constexpr float kEscapeWalkSpeed = 1.0f;  // m/s of the eight walks
class EscapeTable;
struct Shortlist {
  int k = 0;
  int fan = 0;
  float fan_step = 0.0f;
  int fan_k = 1;
  int escapes = 0;
  // Required when escapes > 0, built for (escapes, fan_k) (EscapeTable::shared): the caller that
  // draws the shortlist (the path filter rule, tasks/path_filter.hpp) sets both from one config.
  const EscapeTable* escape_table = nullptr;
};
static_assert(1 + 2 * kMaxShortlistFan <= kMaxShortlistQueries, "shortlist queries");

// Escape e's trajectory (0 <= e < kMaxEscapes) in raw units (12 floats: positions and
// directions at the three horizons, character frame, X left, Z forward).
void escape_trajectory(const Database& db, int e, float* raw);

// For every database frame f, the k nearest valid frames (outside f's exclusion window) of
// each of the first `escapes` escape queries over f's pose: what decision_match's shortlist
// adds for them, found ahead of time (escapes * k int32 per frame, -1 where fewer exist).
class EscapeTable {
 public:
  // Builds the table over the matcher's rows (db's normalized features) on `threads` threads.
  EscapeTable(const Database& db, const Matcher& matcher, int escapes, int k, int threads);
  // A table built before (a controller file's search.escapes: num_frames x escapes * k); throws
  // std::invalid_argument when its size or an entry (a frame, or -1) is out of range.
  EscapeTable(int64_t num_frames, int escapes, int k, std::vector<int32_t> rows);
  // The table for (escapes, k), shared by every user of `matcher`: `prebuilt` when given (and
  // none is shared yet), else built on first request.
  static std::shared_ptr<const EscapeTable> shared(const Database& db, const Matcher& matcher, int escapes, int k,
                                                   std::shared_ptr<const EscapeTable> prebuilt = nullptr);
  int row_count() const { return row_count_; }  // escapes * k entries per frame
  const int32_t* rows(int64_t frame) const { return &rows_[static_cast<size_t>(frame) * row_count_]; }
  const std::vector<int32_t>& all_rows() const { return rows_; }  // num_frames x row_count

 private:
  int row_count_;
  std::vector<int32_t> rows_;
};

// The queries of a shortlist (1 + 2 * fan rows of kFeatureDim, the first the query itself).
int shortlist_queries(const Database& db, const float* query, const Shortlist& shortlist, float* out);

inline int64_t decision_match(const Database& db, const Matcher& matcher, int64_t frame, const float* query,
                                float* cost = nullptr, float transition_cost = 0.0f,
                                const CandidateFilter* filter = nullptr, const Shortlist& shortlist = {}) {
  const int64_t bound = (frame >= 0 && db.valid[frame]) ? frame : -1;
  int64_t lo = 0, hi = 0;
  if (frame >= 0) {
    const int c = db.frame_clip[frame];
    lo = std::max<int64_t>(db.clip_ranges[c * 2], frame - kMatchExcludeWindow);
    hi = std::min<int64_t>(db.clip_ranges[c * 2 + 1], frame + kMatchExcludeWindow + 1);
  }
  int64_t j;
  if (shortlist.k > 0 && filter != nullptr) {
    float queries[kMaxShortlistQueries * kFeatureDim];
    const int n = shortlist_queries(db, query, shortlist, queries);
    const EscapeTable* table = shortlist.escapes > 0 && frame >= 0 ? shortlist.escape_table : nullptr;
    j = matcher.match_shortlist(queries, shortlist.k, lo, hi, bound, cost, transition_cost, filter, n, shortlist.fan_k,
                                table ? table->rows(frame) : nullptr, table ? table->row_count() : 0);
  } else {
    j = matcher.match(query, lo, hi, bound, cost, transition_cost, filter);
  }
  // The filter refused everything: retry with the filter it was built over (a request's clips,
  // the clip costs), in the exact search, down to no filter.
  while (j < 0 && filter != nullptr) {
    filter = filter->fallback();
    j = matcher.match(query, lo, hi, bound, cost, transition_cost, filter);
  }
  return j;
}

// One decision: clips the trajectory action to the box [low, high] (12 each), forms the
// query for the current frame and matches it. Returns the frame to play from.
inline int64_t decision_for_action(const Database& db, const Matcher& matcher, int64_t frame, const float* action,
                                 const float* low, const float* high, float* cost = nullptr,
                                 float transition_cost = 0.0f, const CandidateFilter* filter = nullptr,
                                 const Shortlist& shortlist = {}) {
  float query[kFeatureDim];
  float traj[kTrajectoryDim];
  for (int k = 0; k < kTrajectoryDim; ++k) traj[k] = std::min(high[k], std::max(low[k], action[k]));
  decision_query(db, frame, traj, query);
  return decision_match(db, matcher, frame, query, cost, transition_cost, filter, shortlist);
}

// The clip-cost rule, a candidate filter that every decision path (the batched envs, the
// full path, the engine runtime) builds from one option: costs[c] is added to the match cost
// of every frame of clip c (squared normalized feature distance; +inf: clip c never plays,
// unless the filter refuses every frame). No costs: the filter is off (active() is false). A
// candidate without a row (a compressed controller's state) has no clip and costs nothing more.
class ClipCostFilter final : public CandidateFilter {
 public:
  ClipCostFilter() = default;
  // Throws std::invalid_argument unless costs is empty or has one entry per clip of db, each
  // >= 0 (+inf allowed); the message names `option`.
  ClipCostFilter(const Database& db, std::vector<float> costs, const char* option = "clip_costs");
  bool active() const { return !costs_.empty(); }
  // The filter to hand to decision_for_action: this one, or null when off.
  const CandidateFilter* get() const { return active() ? this : nullptr; }
  float extra_cost(const Candidate& c) const override {
    return c.row < 0 ? 0.0f : costs_[static_cast<size_t>(frame_clip_[c.row])];
  }

 private:
  const int32_t* frame_clip_ = nullptr;
  std::vector<float> costs_;
};

// Normalized trajectory features <-> raw (meters, unit directions) in the character frame.
inline void trajectory_denormalize(const Database& db, const float* normalized, float* raw) {
  const auto scale = db.normalization.column_scale();
  for (int k = 0; k < kTrajectoryDim; ++k)
    raw[k] = normalized[k] * scale[kPoseDim + k] + db.normalization.mean[kPoseDim + k];
}
inline void trajectory_normalize(const Database& db, const float* raw, float* normalized) {
  const auto scale = db.normalization.column_scale();
  for (int k = 0; k < kTrajectoryDim; ++k)
    normalized[k] = (raw[k] - db.normalization.mean[kPoseDim + k]) / scale[kPoseDim + k];
}

// Per-dimension box for trajectory actions in normalized units: mean +- limit_std * std
// over the valid frames (low, high: 12 each).
void trajectory_action_box(const Database& db, float limit_std, float* low, float* high);

}  // namespace mmrl
