#include "mmrl/compressed_source.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "mmrl/character.hpp"

namespace mmrl {

CompressedSource::CompressedSource(const Database& db, const CompressedModel& model, const float* frame_states)
    : db_(&db), model_(&model), frame_states_(frame_states) {
  model.check();
  if (!model.prepared()) throw std::invalid_argument("set_compressed: the model is not prepared (prepare())");
  if (model.num_joints != db.num_joints)
    throw std::invalid_argument("the compressed model has " + std::to_string(model.num_joints) +
                                " joints, the database " + std::to_string(db.num_joints));
  if (frame_states == nullptr) throw std::invalid_argument("set_compressed: frame_states is null");
}

void CompressedSource::prepare(MotionState& s, int frames_per_step) const {
  auto c = std::make_unique<CompressedState>();
  const size_t S = static_cast<size_t>(model_->state_dim());
  c->shown.assign(S, 0.0f);
  c->chosen.assign(S, 0.0f);
  c->next.assign(S, 0.0f);
  c->rows.assign(static_cast<size_t>(frames_per_step + 1) * model_->pose_dim(), 0.0f);
  c->scratch = model_->make_scratch();
  s.own = std::move(c);
}

void CompressedSource::set_state(MotionState& s, const float* state) const {
  std::vector<float>& shown = CompressedState::of(s).shown;
  for (size_t k = 0; k < shown.size(); ++k)
    if (!std::isfinite(state[k])) throw std::invalid_argument("set_state: the state is not finite");
  std::copy(state, state + shown.size(), shown.begin());
}

void CompressedSource::start(MotionState& s, int64_t frame) const {
  if (frame == -1) return;  // keep the state
  s.frame = frame;
  const size_t S = static_cast<size_t>(model_->state_dim());
  const float* row = frame_states_ + static_cast<size_t>(frame) * S;
  std::copy(row, row + S, CompressedState::of(s).shown.begin());
}

Decision CompressedSource::decide(MotionState& s, const float* query, const DecisionRules& rules) const {
  // The filter prices the projections; with a projections fan the query's turned copies are
  // projected too.
  float queries[kMaxShortlistQueries * kFeatureDim];  // shortlist_queries' bound (compressed_decision takes <= 8)
  const int n = shortlist_queries(*db_, query, rules.projections, queries);
  CompressedState& c = CompressedState::of(s);
  Decision d;
  d.transition = compressed_decision(*model_, c.shown.data(), queries, n, rules.transition_cost, rules.filter,
                                     c.chosen.data(), &d.cost, c.scratch);
  if (!d.transition) std::copy(c.shown.begin(), c.shown.end(), c.chosen.begin());
  const int frames = static_cast<int>(c.rows.size() / static_cast<size_t>(model_->pose_dim())) - 1;
  compressed_playback(*model_, c.chosen.data(), frames, c.rows.data(), c.next.data(), c.scratch);
  return d;
}

void CompressedSource::play(Character& character, const MotionState& s, const Decision& d) const {
  play_compressed_rows(character, CompressedState::of(s).rows.data(), d.transition, d.cost, d.anchor);
}

void CompressedSource::show(Character& character, MotionState& s, const RootState& root) const {
  CompressedState& c = CompressedState::of(s);
  model_->decode(c.shown.data(), c.rows.data(), c.scratch);
  show_compressed_row(character, c.rows.data(), root);
}

void CompressedRows::pose(int k, FramePose& out) const {
  const float* r = row(k);
  for (int j = 0; j < J_; ++j) {
    out.rotations[j] = rotation_from_6d(r + 6 * j);
    out.translations[j] = Vec3(r[6 * J_ + 3 * j], r[6 * J_ + 3 * j + 1], r[6 * J_ + 3 * j + 2]);
  }
  for (int c = 0; c < 3; ++c) out.root_delta[c] = r[9 * J_ + c];
  contacts(k, out.contacts);
}

void CompressedRows::contacts(int k, uint8_t out[2]) const {
  const float* r = row(k);
  out[0] = r[9 * J_ + 3] > 0.5f;
  out[1] = r[9 * J_ + 4] > 0.5f;
}

void CompressedRows::velocity_pair(int k, const FramePose& before, FramePose& a, FramePose& b) const {
  if (k > 0)
    a = before;
  else
    pose(0, a);
  pose(k, b);
}

void show_compressed_row(Character& character, const float* row, const RootState& root) {
  character.show(CompressedRows(row, character.num_joints()), root);
}

void play_compressed_rows(Character& character, const float* rows, bool transition, float cost,
                          const float* anchor) {
  character.play(CompressedRows(rows, character.num_joints()), transition, cost, anchor);
}

}  // namespace mmrl
