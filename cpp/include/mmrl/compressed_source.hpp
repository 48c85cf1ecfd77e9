// A compressed controller (compressed.hpp) as a motion source (decider.hpp): the candidates of
// a decision are the continuation (the state played now) and the projector's states of the
// query and of its turned copies (DecisionRules::projections), each priced by the candidate
// filters as a candidate without a row; playback steps the chosen state and decodes its pose
// rows. A start from database frame f takes f's stored state (frame_states: one row of
// state_dim floats per database frame).
//
// The state of a character (MotionState): cstate, the state shown now; cchosen, the one the last
// decision chose (the projection, or cstate); cnext, the state after that decision's playback;
// crows, its (frames_per_step + 1) pose rows (row 0 the chosen state's pose, rows 1.. shown).
#pragma once

#include "mmrl/decider.hpp"

namespace mmrl {

class CompressedSource final : public MotionSource {
 public:
  // db, model and frame_states are borrowed and must outlive the source. Throws
  // std::invalid_argument for a model that is not prepared, of another skeleton, or without states.
  CompressedSource(const Database& db, const CompressedModel& model, const float* frame_states);
  const CompressedModel& model() const { return *model_; }

  void prepare(MotionState& s, int frames_per_step) const override;
  bool rowless_candidates() const override { return true; }
  bool starts_at(int64_t frame) const override { return frame == -1 || (frame >= 0 && frame < db_->num_frames); }
  void start(MotionState& s, int64_t frame) const override;
  Candidate current(const MotionState& s) const override { return Candidate{-1, s.cstate.data()}; }
  bool can_continue(const MotionState&) const override { return true; }
  Decision decide(MotionState& s, const float* query, const DecisionRules& rules) const override;
  Candidate chosen(const MotionState& s, const Decision&) const override { return Candidate{-1, s.cchosen.data()}; }
  const float* played_delta(const MotionState& s, const Decision&, int k) const override {
    return &s.crows[static_cast<size_t>(k) * model_->pose_dim() + 9 * model_->num_joints];
  }
  void end_playback(MotionState& s, const Decision&, int) const override {
    std::copy(s.cnext.begin(), s.cnext.end(), s.cstate.begin());
  }
  void play(Character& character, const MotionState& s, const Decision& d) const override;
  void show(Character& character, MotionState& s, const RootState& root) const override;
  int state_dim() const override { return model_->state_dim(); }
  size_t memory_bytes() const override {
    return model_->memory_bytes() + sizeof(float) * static_cast<size_t>(db_->num_frames) * model_->state_dim();
  }
  const float* frame_states() const { return frame_states_; }
  void set_state(MotionState& s, const float* state) const override;

 private:
  const Database* db_;
  const CompressedModel* model_;
  const float* frame_states_;
};

}  // namespace mmrl
