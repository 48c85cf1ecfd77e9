// The collision-aware search: a registered candidate rule (rules.hpp, "path-filter") that
// tests the path each candidate frame would play against where every obstacle will be at that
// time, so the match prefers clips that stay clear. The idea is environment-aware motion
// matching (Ponton, Andrews, Andujar, Pelechano 2025: collision costs inside the search), here as
// one rule that the training env, the full path, the engine runtime and mmrl play all run
// through TargetTask::decide.
//
// The rule, for a character at root (x, z, yaw) and a candidate frame j:
//   - j's path: the root positions that playing from j reaches kPathSampleFrames[s] frames
//     later (Database::path_samples, placed through the character's current root), for the
//     samples s with kPathSampleFrames[s] <= horizon (frames);
//   - the obstacles at sample s: where the env's own motion rule (constant velocity, mirrored
//     at the square's border; ObstacleField::path) puts them after that many frames;
//   - j hits at s when a disc of `radius` (the body radius plus a margin covering the frames
//     between samples) around its path point overlaps an obstacle there. The extra cost of j
//     is cost * (2 - t_s / horizon) for its first hit at t_s = kPathSampleFrames[s] frames
//     (twice the cost for a hit right away, the cost itself at the horizon), 0 for a clear
//     path; cost = +inf refuses every candidate that hits. Costs add to the rules' below it.
// The continuation is a candidate like any other: it keeps its transition-cost advantage while
// its path is clear, and loses it (plus the hit's cost) when it is not. A compressed
// controller's candidate (a state, no database row) is priced by the same method, its path
// drawn from its own trajectory features (trajectory_path). The filter only adds
// costs, so the KD-tree search stays exact under it (tested against brute force).
//
// Cost: prepare() runs once per decision (the obstacles near enough to reach a path point,
// their positions at every sample); extra_cost runs only for rows whose distance alone could
// still win (kdtree.hpp), each a loop over samples x nearby obstacles with a bounding-circle
// reject first, over only the obstacles a path point of that sample can reach (an early sample
// reaches a few). No allocation after init().
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "mmrl/database.hpp"
#include "mmrl/decision.hpp"
#include "mmrl/grid.hpp"
#include "mmrl/kdtree.hpp"
#include "mmrl/rules.hpp"

namespace mmrl {

// One character's obstacles as a decision's rules see them (RuleContext::obstacles): env `env`
// of `field`, seen from a character at `root`, moved by the env's rule when `moving` (frame_dt
// seconds per frame) and frozen otherwise.
struct ObstacleScene {
  const ObstacleField* field = nullptr;
  int env = 0;
  RootState root;
  bool moving = false;
  float frame_dt = 0;
};

// The collision-aware search as a registered candidate rule (rules.cpp's "path-filter" line):
// built for an ObstacleTaskConfig with path_filter on (else null). Before each decision that has
// a scene it prices every candidate's played path against the obstacles (ObstaclePathFilter
// below, with path_cost, path_horizon, body_radius + path_margin) and asks for its shortlist:
// path_candidates nearest plus the path_escapes' path_fan_candidates nearest each (the escape
// table, shared per matcher), and for a compressed controller the query turned by
// +-1..compressed_path_fan x path_fan_degrees. std::invalid_argument for a bad config.
std::unique_ptr<CandidateRule> make_path_filter_rule(const RuleSetup& setup);

struct PathFilterConfig {
  float radius = 0.3f;   // disc around each path point (meters)
  float cost = 100.0f;   // squared normalized feature distance; +inf refuses
  int horizon = 30;      // frames; kPathSampleFrames[0] <= horizon <= kPathSampleFrames[last]
};

// The path a trajectory implies (raw trajectory features, 12 floats: features.hpp's layout):
// the root's (x, z) kPathSampleFrames[s] frames ahead (kPathSamples x 2, character frame), by
// quadratic interpolation through the start (0, 0) and the trajectory's three positions
// (kTrajectoryOffsets: 10, 20, 30 frames), the samples before 10 frames through 0, 10 and 20,
// the later ones through 10, 20 and 30. For a database frame the 10-, 20- and 30-frame samples
// equal its path samples (tests/test_compressed_obstacles.py bounds the others); a state's test
// pulls points beyond kStateReach in to it, whatever the database (so the runtime's start
// windows and the training database give the same test).
void trajectory_path(const float* raw_trajectory, float* path);

class ObstaclePathFilter final : public CandidateRule {
 public:
  ObstaclePathFilter() = default;
  // Sizes the filter for up to `capacity` obstacles. Throws std::invalid_argument for a config
  // out of range or a database without path samples.
  void init(const Database& db, int capacity, const PathFilterConfig& config);
  // The shortlist and projections it asks a decision for as a rule (shape), and the escape table
  // the shortlist reads (kept alive here; null without escapes).
  void set_shortlist(const Shortlist& shortlist, const Shortlist& projections,
                     std::shared_ptr<const EscapeTable> escapes) {
    shortlist_ = shortlist, projections_ = projections, escapes_ = std::move(escapes);
    shortlist_.escape_table = escapes_.get();
  }
  // Prepares one decision: env's obstacles of `field` seen from a character at `root`, moved by
  // the env's rule when `moving` (frame_dt seconds per frame) and frozen otherwise.
  void prepare(const ObstacleField& field, int env, const RootState& root, bool moving, float frame_dt);

  // How far a compressed state's path may reach (meters, 30 frames: faster than any
  // locomotion): its points beyond are pulled in to it (first_hit_state), and with
  // set_prices_states(true) prepare() looks that far too, so a state's test depends on no database.
  static constexpr float kStateReach = 6.0f;
  void set_prices_states(bool on) {
    states_ = on;
    prepared_ = false;
  }

  // As a rule: prepares for the context's obstacles (off without them: a character with none)
  // and asks for its shortlist.
  bool prepare(const RuleContext& context) override;
  void shape(DecisionRules& rules) const override {
    rules.shortlist = shortlist_;
    rules.projections = projections_;
  }
  // The first sample index s at which a candidate's path hits (kPathSampleFrames[s] frames
  // ahead), or -1. A database row's path is its path samples; a candidate without a row (a
  // compressed controller's state) has trajectory_path of its own trajectory features, tested
  // the same way (set_prices_states(true) first).
  int first_hit(const Candidate& c) const { return c.row >= 0 ? first_hit(c.row) : first_hit_state(c.features); }
  int first_hit(int64_t row) const { return first_hit_path(paths_ + static_cast<size_t>(row) * kPathSamples * 2); }
  // The same for a state's features, and for a path (kPathSamples x (x, z), meters in the
  // character frame, within prepare()'s reach).
  int first_hit_state(const float* features) const;
  int first_hit_path(const float* path) const;
  // Obstacles near enough to matter for this decision (for tests and benches).
  int nearby() const { return kept_; }

 private:
  float cost(const Candidate& c) const override {
    const int s = first_hit(c);
    return s < 0 ? 0.0f : hit_cost_[s];
  }

  const Database* db_ = nullptr;
  const float* paths_ = nullptr;  // db.path_samples
  Shortlist shortlist_, projections_;
  std::shared_ptr<const EscapeTable> escapes_;
  PathFilterConfig config_;
  float reach_ = 0;  // farthest path point within the horizon (meters)
  bool states_ = false;  // set_prices_states
  int samples_ = 0, capacity_ = 0, kept_ = 0;
  float hit_cost_[kPathSamples] = {};
  float root_x_ = 0, root_z_ = 0, cos_yaw_ = 1, sin_yaw_ = 0;
  // What the last prepare() was for (prepare skips a call for the same state).
  struct PreparedFor {
    const ObstacleField* field = nullptr;
    int env = -1;
    uint64_t generation = 0;
    float x = 0, z = 0, yaw = 0;
    bool moving = false;
    float frame_dt = 0;
    bool operator==(const PreparedFor& o) const {
      return field == o.field && env == o.env && generation == o.generation && x == o.x && z == o.z &&
             yaw == o.yaw && moving == o.moving && frame_dt == o.frame_dt;
    }
  };
  PreparedFor prepared_for_;
  bool prepared_ = false;
  std::vector<float> cx_, cz_;  // samples_ x capacity_, sample-major: kept obstacles' centres
  std::vector<float> ocos_, osin_, hx_, hz_, bound2_;  // per kept obstacle
  std::vector<int32_t> near_;                          // samples_ x capacity_: per sample, the kept ones it can reach
  int near_count_[kPathSamples] = {};
  std::vector<float> scratch_x_, scratch_z_;           // one obstacle's positions per frame
};

}  // namespace mmrl
