// A compressed controller (compressed.hpp) as a motion source (decider.hpp): the candidates of
// a decision are the continuation (the state played now) and the projector's states of the
// query and of its turned copies (DecisionRules::projections), each priced by the candidate
// filters as a candidate without a row; playback steps the chosen state and decodes its pose
// rows. A start from database frame f takes f's stored state (frame_states: one row of
// state_dim floats per database frame).
//
// The state of a character (MotionState::own, a CompressedState): shown, the state shown now;
// chosen, the one the last decision chose (the projection, or shown); next, the state after that
// decision's playback; rows, its (frames_per_step + 1) pose rows (row 0 the chosen state's pose,
// rows 1.. shown).
#pragma once

#include <cassert>

#include "mmrl/character.hpp"
#include "mmrl/compressed.hpp"
#include "mmrl/decider.hpp"

namespace mmrl {

// Floats of one pose row of a compressed controller of num_joints joints (compressed.hpp:
// 6D rotations, translations, root delta, contacts).
constexpr int pose_row_dim(int num_joints) { return 9 * num_joints + 5; }

// A compressed controller's decoded pose rows as a character plays them (character.hpp): frame
// k is row k (no database frame); a frame's velocity is the backward difference from the pose
// shown before it (row 0 stands still).
class CompressedRows final : public PlayedFrames {
 public:
  // rows: at least one row of pose_row_dim(num_joints) floats per frame asked for, borrowed.
  CompressedRows(const float* rows, int num_joints) : rows_(rows), J_(num_joints) {}
  int64_t frame(int) const override { return -1; }
  void pose(int k, FramePose& out) const override;
  const float* root_delta(int k) const override { return row(k) + 9 * J_; }
  void contacts(int k, uint8_t out[2]) const override;
  void velocity_pair(int k, const FramePose& before, FramePose& a, FramePose& b) const override;

 private:
  const float* row(int k) const { return rows_ + static_cast<size_t>(k) * pose_row_dim(J_); }
  const float* rows_;
  int J_;
};

// Shows a compressed controller's start, pose row `row`, at the world root (frame() is -1 from
// now on: no database frame is shown).
void show_compressed_row(Character& character, const float* row, const RootState& root);
// Plays a compressed controller's decision (the env's): rows are (frames_per_step + 1) pose
// rows, row 0 the chosen state's pose and rows 1.. the frames shown. transition: the projection
// replaced the state played so far. anchor: the decision's (Decision::anchor), or null.
void play_compressed_rows(Character& character, const float* rows, bool transition, float cost,
                          const float* anchor = nullptr);

struct CompressedState final : SourceState {
  std::vector<float> shown, chosen, next, rows;
  CompressedScratch scratch;
  std::unique_ptr<SourceState> clone() const override { return std::make_unique<CompressedState>(*this); }
  // The compressed part of a state a CompressedSource prepared.
  static CompressedState& of(MotionState& s) {
    assert(s.own);
    return static_cast<CompressedState&>(*s.own);
  }
  static const CompressedState& of(const MotionState& s) {
    assert(s.own);
    return static_cast<const CompressedState&>(*s.own);
  }
};

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
  Candidate current(const MotionState& s) const override { return Candidate{-1, CompressedState::of(s).shown.data()}; }
  Decision decide(MotionState& s, const float* query, const DecisionRules& rules) const override;
  Candidate chosen(const MotionState& s, const Decision&) const override {
    return Candidate{-1, CompressedState::of(s).chosen.data()};
  }
  const float* played_delta(const MotionState& s, const Decision&, int k) const override {
    return &CompressedState::of(s).rows[static_cast<size_t>(k) * model_->pose_dim() + 9 * model_->num_joints];
  }
  void end_playback(MotionState& s, const Decision&, int) const override {
    CompressedState& c = CompressedState::of(s);
    std::copy(c.next.begin(), c.next.end(), c.shown.begin());
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
