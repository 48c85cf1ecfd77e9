// The decision engine of one character, and the interface of the motion it decides over.
//
// A decision (decision.hpp has the rule and its numbers): the action (12 normalized
// trajectory floats) is clipped to the action box, the query is the pose features of what is
// shown now followed by that trajectory, and the motion source picks the candidate of least
// cost under the decision's rules (the transition cost, the chain of candidate filters and
// how their shortlist is drawn), falling back down the chain when every candidate is refused.
// The result is one Decision record, which the source then plays: as root motion on the fast
// path (played_delta, end_playback) and as poses on a Character (play).
//
// Two motion sources implement MotionSource: the database (database_source.hpp: candidates are
// database rows, playback reads the rows that follow) and a compressed controller
// (compressed_source.hpp: candidates are the projector's states, playback steps and decodes the
// networks). Every caller (the batched envs, the full path, the engine runtime, the C interface,
// mmrl play) decides through a Decider and plays through the source; nothing else asks which
// source it has. A candidate filter prices both kinds of candidate through its one method
// (kdtree.hpp's Candidate: a row, or a state without one).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "mmrl/decision.hpp"

namespace mmrl {

class Character;

// What one decision chose.
struct Decision {
  int64_t match = -1;          // the database frame played from (frames match+1 .. shown); -1: a state, no row
  bool transition = false;     // the choice is not the continuation of what was playing
  float cost = 0;              // the chosen candidate's squared distance to the query plus its filters' costs
  float transition_cost = 0;   // the transition cost the decision used
  // Squared normalized, weighted distance between the pose features (kPoseDim) of the
  // continuation and of the choice: what a transition asks the blend to hide; 0 without one.
  float pose_jump = 0;
  // The root's move at a transition that keeps the planted feet where they stand (dx, dz in the
  // character frame; DecisionRules::anchor): played before the first frame, by the env on its root
  // and by a Character on its root and blend. (0, 0) otherwise.
  float anchor[2] = {0, 0};
};

// What a task changes in a decision: the transition cost, the head of its candidate-filter
// chain (each filter falls back to the one it was built over), and how the filter sees its
// candidates: the database's shortlist (decision.hpp's Shortlist; k = 0: the exact filtered
// search) and, for a compressed controller, the turned queries it projects (fan only).
struct DecisionRules {
  float transition_cost = 0;
  const CandidateFilter* filter = nullptr;
  Shortlist shortlist;
  Shortlist projections;
  // Anchor a transition on the planted feet (Decider::decide): when both feet are planted in the
  // pose shown and in the chosen one, the root moves by minus their mean offset between the two,
  // so they stay where they stand while the blend moves the body over them (a task asks for it:
  // the arrive task's stand, stand_anchor).
  bool anchor = false;
};

// What a source keeps of a character beyond MotionState::frame (a compressed controller's
// states, rows and scratch): its prepare() makes it, and only that source reads it.
struct SourceState {
  virtual ~SourceState() = default;
  virtual std::unique_ptr<SourceState> clone() const = 0;
};

// One character's place in its motion source. A database source keeps `frame` (the frame
// shown now); a compressed source keeps the state shown now and its playback in `own` (its file
// says how), and `frame` is the database frame its state started from.
struct MotionState {
  int64_t frame = 0;
  std::unique_ptr<SourceState> own;  // the source's own part (null for the database's)
  MotionState() = default;
  MotionState(const MotionState& o) : frame(o.frame), own(o.own ? o.own->clone() : nullptr) {}
  MotionState(MotionState&&) = default;
  MotionState& operator=(const MotionState& o) {
    if (this != &o) {
      frame = o.frame;
      own = o.own ? o.own->clone() : nullptr;
    }
    return *this;
  }
  MotionState& operator=(MotionState&&) = default;
};

class MotionSource {
 public:
  virtual ~MotionSource() = default;
  // Sizes what s needs to play frames_per_step frames per decision (allocates; once per state).
  virtual void prepare(MotionState& s, int frames_per_step) const = 0;
  // Whether `frame` is a start start() accepts: a database frame (a compressed source also
  // takes -1: keep the state it has).
  virtual bool starts_at(int64_t frame) const = 0;
  // Puts s on database frame `frame` (starts_at(frame) must hold).
  virtual void start(MotionState& s, int64_t frame) const = 0;
  // The candidate shown now: its continuation is the decision's starting best.
  virtual Candidate current(const MotionState& s) const = 0;
  // The decision for a query (kFeatureDim normalized floats) under `rules`: match, transition
  // and cost (pose_jump and transition_cost are the Decider's). Writes d's playback into s.
  virtual Decision decide(MotionState& s, const float* query, const DecisionRules& rules) const = 0;
  // The candidate decision d chose (its continuation when d is not a transition).
  virtual Candidate chosen(const MotionState& s, const Decision& d) const = 0;
  // The root delta (dx, dz in its own character frame, dyaw) of d's k-th played frame.
  virtual const float* played_delta(const MotionState& s, const Decision& d, int k) const = 0;
  // Moves s to the end of d's playback (frames_per_step frames).
  virtual void end_playback(MotionState& s, const Decision& d, int frames_per_step) const = 0;
  // Plays d's frames on a character (inertialization, foot locking, IK) from the pose it shows.
  virtual void play(Character& character, const MotionState& s, const Decision& d) const = 0;
  // Whether candidates come without database rows (compressed states): a filter then prices
  // them by their features alone (the path filter draws their paths from their trajectories).
  virtual bool rowless_candidates() const = 0;
  // Puts a character on what s shows now, at the world root (no blend, no locks).
  virtual void show(Character& character, MotionState& s, const RootState& root) const = 0;
  // The floats of a state a caller may set (set_state): 0 when what is shown is a database
  // frame and nothing more.
  virtual int state_dim() const { return 0; }
  // Bytes the source holds beyond the database and its search tree (a compressed controller's
  // networks and start states).
  virtual size_t memory_bytes() const { return 0; }
  // Sets what s shows from state_dim() floats (std::invalid_argument when not finite, or when
  // the source has no such state).
  virtual void set_state(MotionState& s, const float* state) const;
};

// The decision engine: the action box and one rule for every character and every source.
class Decider {
 public:
  Decider() = default;
  // The box of db's trajectory features: mean +- limit_std * std over the valid frames
  // (normalized units); limit_std <= 0: actions are not clipped.
  Decider(const Database& db, float action_limit_std);
  // Replaces the box (12 + 12 normalized floats, low <= high; std::invalid_argument otherwise):
  // a controller file whose database holds only its start frames carries the training box.
  void set_action_box(const float* low, const float* high);
  const float* action_low() const { return low_; }
  const float* action_high() const { return high_; }

  // The decision of a character in state s for `action` (12 normalized floats, finite; checked
  // by the caller) under `rules`, over `source`. Changes only s's playback buffers.
  Decision decide(const MotionSource& source, MotionState& s, const float* action, const DecisionRules& rules) const;

 private:
  // d.anchor for a transition from the candidate shown (now) to the chosen one (normalized features).
  void anchor(const float* now, const float* chosen, Decision& d) const;
  float low_[kTrajectoryDim] = {}, high_[kTrajectoryDim] = {};
  float pose_mean_[kPoseDim] = {}, pose_scale_[kPoseDim] = {};  // the pose features' normalization
};

}  // namespace mmrl
