// The batched target-reaching environment, shared by every task (tasks/plane.hpp,
// tasks/obstacles.hpp): N characters step in one call over a thread pool, writing
// observations, rewards and flags into caller-owned buffers (numpy arrays in Python).
// Nothing is allocated per step.
//
// What every task shares, and this template owns:
//   - the database and matcher (borrowed), the config, one state per environment;
//   - one RNG per environment, seeded from (seed, index): results never depend on the
//     thread count or on scheduling;
//   - the valid start frames and the action box (mean +- action_limit_std * std of the
//     trajectory features over the valid frames, normalized units);
//   - the constructor checks common to all tasks;
//   - autoreset, in gymnasium's two modes. SAME_STEP (the default): an environment whose
//     episode ended writes its last observation to final_obs, its return and length, and is
//     reset at once, its first observation in obs. NEXT_STEP (what RLlib expects): the ending
//     step writes the last observation to obs (and final_obs), and the env's next step ignores
//     its action, resets it and returns the first observation with reward 0 and no flags.
//     Each env draws its episodes from its own RNG, so both modes play the same episodes;
//   - the bookkeeping: steps, truncation at max_steps, episode return, frames played.
//
// A task is a class Task deriving from TargetVecEnv<Task, Config, State> (CRTP) that defines
//   static constexpr int kObsDim, kActionDim;  (kObsDim: the base observation's size)
//   int obs_dim() const;                       (this env's, >= kObsDim with optional segments)
//   void observe(int i, float* obs_row) const;        // env i's observation now
//   void begin_episode(int i);                         // draws env i's episode (its RNG only)
//   TaskStep advance(int i, const float* action);     // one RL step of env i, no autoreset
// and nothing else of the loop. Config derives from TaskConfig (tasks/task_config.hpp);
// State derives from TargetEnvState (target_env.hpp, with the step records and start rules).
//
// size: one class template of two halves, the database decision and the compressed one
// (set_compressed .. decide_compressed), kept together because each mirrors the other's
// hooks; what both share outside the class is in target_env.hpp and decision.hpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

#include "mmrl/target_env.hpp"
#include "mmrl/threadpool.hpp"

namespace mmrl {


template <class Task, class Config, class State>
class TargetVecEnv {
 public:
  int num_envs() const { return static_cast<int>(envs_.size()); }
  const Config& config() const { return config_; }
  const Database& database() const { return db_; }
  const float* action_low() const { return low_; }
  const float* action_high() const { return high_; }
  State& state(int i) { return envs_[i]; }
  const State& state(int i) const { return envs_[i]; }
  // Autoreset mode (see the header comment): false = SAME_STEP, true = NEXT_STEP. Switching
  // applies from the next step; an env whose reset is pending still gets it.
  void set_autoreset_next_step(bool on) { next_step_autoreset_ = on; }
  bool autoreset_next_step() const { return next_step_autoreset_; }

  // Reseeds every environment's RNG from (seed, index) and resets all; obs: N x obs_dim() (or null).
  void reset(uint64_t seed, float* obs) {
    for (int i = 0; i < num_envs(); ++i) {
      envs_[i].rng = Rng(seed, static_cast<uint64_t>(i));
      envs_[i].last_step_frames = 0;
      envs_[i].last_step_transition = false;
      envs_[i].last_step_cost = 0;
      envs_[i].last_step_match = -1;
      envs_[i].last_step_transition_cost = 0;
    }
    pool_.parallel_for(num_envs(), [&](int64_t b, int64_t e, int) {
      for (int64_t i = b; i < e; ++i) reset_env(static_cast<int>(i), obs ? obs + i * task().obs_dim() : nullptr);
    });
  }

  // Resets environment i from its own RNG stream; writes its observation row (if not null).
  void reset_env(int i, float* obs_row) {
    State& s = envs_[i];
    if (!s.request_pinned && !request_mix_.empty())  // the episode's request, before its start is drawn
      s.request_index = static_cast<int>(request_mix_.pick(s.rng.uniform()));
    task().begin_episode(i);
    start_compressed(s);
    s.autoreset_pending = false;
    s.episode_frames = 0;
    s.steps = 0;
    s.episode_return = 0;
    s.last_match = -1;
    s.last_transition = false;
    s.last_cost = 0;
    s.last_transition_cost = 0;
    s.last_pose_jump = 0;
    if (obs_row) task().observe(i, obs_row);
  }

  // A new target for env i by the episode start's rule, around where its character stands now
  // (half_extent > min_target_distance, else std::invalid_argument), from env i's RNG; sets it.
  void draw_target_around_root(int i, float half_extent) {
    if (!(half_extent > config_.min_target_distance) || !std::isfinite(half_extent))
      throw std::invalid_argument("half_extent must be finite and larger than min_target_distance");
    State& s = envs_[i];
    float dx = 0, dz = 0;
    draw_target_offset(s.rng, half_extent, config_.min_target_distance, &dx, &dz);
    s.target_x = s.root.x + dx;
    s.target_z = s.root.z + dz;
  }

  // Requests (tags.hpp). The observation ends with request_dim() floats: the code of env i's
  // request over the config's request_groups (0 without them).
  int request_dim() const { return request_code_.dim(); }
  const RequestCode& request_code() const { return request_code_; }
  const RequestMix& request_mix() const { return request_mix_; }
  // Pins env i's request: from its next decision on, env i matches only frames of the clips
  // carrying it, and its episodes start there; "" unpins (the env draws a request per episode
  // again when the config has request_groups, else plays every clip). Throws
  // std::invalid_argument naming an unknown group or tag, or when it selects no valid frame
  // (listing the tags available); env i is then unchanged.
  void set_request(int i, const std::string& text) {
    State& s = envs_[i];
    if (text.find_first_not_of(" \t") == std::string::npos) {
      s.request_pinned = false;
      s.request_index = -1;
      s.pinned_request = RequestSelection{};
      s.pinned_code.clear();
      return;
    }
    RequestSelection sel = select_request(db_, text);
    std::vector<float> code(static_cast<size_t>(request_dim()));
    request_code_.encode(sel.request, code.data());
    s.pinned_request = std::move(sel);
    s.pinned_code = std::move(code);
    s.request_pinned = true;
  }
  // Env i's request now (a pinned one, or the episode's draw; every clip: request.text "").
  const RequestSelection& request(int i) const {
    const State& s = envs_[i];
    if (s.request_pinned) return s.pinned_request;
    if (s.request_index >= 0) return request_mix_.selections[static_cast<size_t>(s.request_index)];
    return every_clip_;
  }
  bool request_pinned(int i) const { return envs_[i].request_pinned; }

  // Compressed controllers (compressed.hpp). With a model, every env plays it instead of the
  // database: the observation's pose features are those of the env's state, a decision
  // projects the query (compressed_decision: the continuation rule with the task's transition
  // cost) and playback steps and decodes the networks (compressed_playback). Episode starts
  // still draw a database frame and start from its state: frame_states holds one row of
  // state_dim floats per database frame (both borrowed, alive while set). Requests and clip
  // costs do not apply to a projection; a task filter that prices states does
  // (CandidateFilter::state_extra_cost: the obstacles task's collision-aware search, over the
  // projections of its compressed_shortlist's queries). nullptr: back to the database.
  // Throws std::invalid_argument for a model of another skeleton, or a task that cannot play
  // one (Task::kPlaysCompressed).
  void set_compressed(const CompressedModel* model, const float* frame_states) {
    if (model == nullptr) {
      compressed_ = nullptr;
      compressed_states_ = nullptr;
      task().on_compressed_set();
      return;
    }
    if (!Task::kPlaysCompressed)
      throw std::invalid_argument("this task does not play compressed controllers (the plane and obstacles tasks do)");
    model->check();
    if (!model->prepared()) throw std::invalid_argument("set_compressed: the model is not prepared (prepare())");
    if (model->num_joints != db_.num_joints)
      throw std::invalid_argument("the compressed model has " + std::to_string(model->num_joints) +
                                  " joints, the database " + std::to_string(db_.num_joints));
    if (frame_states == nullptr) throw std::invalid_argument("set_compressed: frame_states is null");
    const size_t S = static_cast<size_t>(model->state_dim());
    for (State& s : envs_) {
      s.cstate.assign(S, 0.0f);
      s.cchosen.assign(S, 0.0f);
      s.cnext.assign(S, 0.0f);
      s.crows.assign(static_cast<size_t>(config_.frames_per_step + 1) * model->pose_dim(), 0.0f);
      s.cscratch = model->make_scratch();
    }
    compressed_ = model;
    compressed_states_ = frame_states;
    for (int i = 0; i < num_envs(); ++i) start_compressed(envs_[i]);
    task().on_compressed_set();
  }
  const CompressedModel* compressed() const { return compressed_; }
  // Moves env i's compressed state to the end of its last decision's playback: what a step does
  // after deciding, for a caller that only decides (the engine runtime, whose character plays).
  void end_compressed_playback(int i) {
    if (compressed_ != nullptr) std::copy(envs_[i].cnext.begin(), envs_[i].cnext.end(), envs_[i].cstate.begin());
  }
  // The state at the end of env i's last playback (kept through the autoreset, so a caller
  // can go on from where the episode ended: set_compressed_state, then set_state with frame -1).
  const float* compressed_played(int i) const { return envs_[i].cnext.data(); }
  // Sets env i's compressed state (state_dim floats, finite; std::invalid_argument otherwise).
  void set_compressed_state(int i, const float* state) {
    if (compressed_ == nullptr) throw std::invalid_argument("set_compressed_state: no compressed controller is set");
    for (size_t k = 0; k < envs_[i].cstate.size(); ++k)
      if (!std::isfinite(state[k])) throw std::invalid_argument("set_compressed_state: the state is not finite");
    std::copy(state, state + envs_[i].cstate.size(), envs_[i].cstate.begin());
  }
  // Replaces the action box (12 + 12 normalized floats, low <= high): a controller file whose
  // database holds only its start frames carries the training database's box.
  void set_action_box(const float* low, const float* high) {
    for (int k = 0; k < kTrajectoryDim; ++k)
      if (!(low[k] <= high[k])) throw std::invalid_argument("action box: low must be <= high in every dimension");
    std::copy(low, low + kTrajectoryDim, low_);
    std::copy(high, high + kTrajectoryDim, high_);
  }
  // Env i's compressed playback: the last decision's pose rows and the state shown now.
  const float* compressed_rows(int i) const { return envs_[i].crows.data(); }
  const float* compressed_state(int i) const { return envs_[i].cstate.data(); }
  // The state env i's last decision chose (the projection, or the continuation).
  const float* compressed_chosen(int i) const { return envs_[i].cchosen.data(); }

  // Moves env i's target (world meters; finite, else std::invalid_argument).
  void set_target(int i, float x, float z) {
    if (!std::isfinite(x) || !std::isfinite(z)) throw std::invalid_argument("target must be finite");
    envs_[i].target_x = x;
    envs_[i].target_z = z;
  }

  // Puts env i's character on database frame `frame` at world (x, z) facing yaw (radians),
  // keeping its target, step count, return and RNG: e.g. to go on from where a full-path
  // character stands. The task refreshes what depends on the root (on_state_set). Throws
  // std::invalid_argument for a frame outside the database or a non-finite root.
  // With a compressed controller, frame -1 keeps env i's compressed state (a database frame
  // starts from that frame's state).
  void set_state(int i, int64_t frame, float x, float z, float yaw) {
    const bool keep = compressed_ != nullptr && frame == -1;
    if (!keep && (frame < 0 || frame >= db_.num_frames)) throw std::invalid_argument("frame is outside the database");
    if (!std::isfinite(x) || !std::isfinite(z) || !std::isfinite(yaw))
      throw std::invalid_argument("root must be finite");
    State& s = envs_[i];
    if (!keep) {
      s.frame = frame;
      start_compressed(s);
    }
    s.root.x = x;
    s.root.z = z;
    s.root.yaw = wrap_angle(yaw);
    task().on_state_set(i);
  }

  // The decision of env i now for `action` (12 normalized floats, finite): the task's
  // transition cost and candidate filter (decision_transition_cost, candidate_filter),
  // decision_for_action, and the frame to play from. Records last_match, last_transition,
  // last_cost, last_transition_cost and last_pose_jump; changes nothing else. A step calls it
  // first; the engine runtime calls it on a one-env env to decide as training did.
  int64_t decide(int i, const float* action) {
    State& s = envs_[i];
    s.last_transition_cost = task().decision_transition_cost(i);
    if (compressed_ != nullptr) return decide_compressed(i, action);
    const CandidateFilter* filter = task().candidate_filter(i);
    const int64_t j = decision_for_action(db_, matcher_, s.frame, action, low_, high_, &s.last_cost, s.last_transition_cost,
                                        filter, task().candidate_shortlist());
    s.last_transition = (j != s.frame);
    s.last_match = j;
    s.last_pose_jump = 0;
    if (s.last_transition) {
      const float* a = &db_.normalized[static_cast<size_t>(s.frame) * kFeatureDim];
      const float* b = &db_.normalized[static_cast<size_t>(j) * kFeatureDim];
      for (int k = 0; k < kPoseDim; ++k) s.last_pose_jump += (a[k] - b[k]) * (a[k] - b[k]);
    }
    return j;
  }

  // The compressed decision of decide(): the query of the state shown now, its projection or
  // the continuation, and the chosen state's playback (s.crows, s.cnext; end_playback moves
  // on). Returns -1: no database frame.
  int64_t decide_compressed(int i, const float* action) {
    State& s = envs_[i];
    float query[kFeatureDim];
    for (int k = 0; k < kPoseDim; ++k) query[k] = s.cstate[k];
    for (int k = 0; k < kTrajectoryDim; ++k) query[kPoseDim + k] = std::min(high_[k], std::max(low_[k], action[k]));
    // The task's filter prices the projections (state_extra_cost: the collision-aware search);
    // with its compressed_shortlist fan, the query's turned copies are projected too.
    float queries[kMaxShortlistQueries * kFeatureDim];  // shortlist_queries' bound (compressed_decision takes <= 8)
    const int n = shortlist_queries(db_, query, task().compressed_shortlist(), queries);
    s.last_transition = compressed_decision(*compressed_, s.cstate.data(), queries, n, s.last_transition_cost,
                                            task().candidate_filter(i),
                                            s.cchosen.data(), &s.last_cost, s.cscratch);
    if (!s.last_transition) std::copy(s.cstate.begin(), s.cstate.end(), s.cchosen.begin());
    s.last_pose_jump = 0;
    if (s.last_transition)
      for (int k = 0; k < kPoseDim; ++k) s.last_pose_jump += (s.cstate[k] - s.cchosen[k]) * (s.cstate[k] - s.cchosen[k]);
    compressed_playback(*compressed_, s.cchosen.data(), config_.frames_per_step, s.crows.data(), s.cnext.data(),
                        s.cscratch);
    s.last_match = -1;
    return -1;
  }

  // Every env's MatchStats since the last call, summed; zeroes them.
  MatchStats pop_match_stats() {
    MatchStats total;
    for (State& s : envs_) {
      total.decisions += s.stats.decisions;
      total.transitions += s.stats.transitions;
      total.frames += s.stats.frames;
      total.cost_sum += s.stats.cost_sum;
      s.stats = MatchStats{};
    }
    return total;
  }

  // Each environment's current database frame (N).
  void current_frames(int64_t* out) const {
    for (int i = 0; i < num_envs(); ++i) out[i] = envs_[i].frame;
  }
  // Each environment's frames played in the last step (N; see TargetEnvState::last_step_frames).
  void last_step_frames(int32_t* out) const {
    for (int i = 0; i < num_envs(); ++i) out[i] = envs_[i].last_step_frames;
  }
  // Each environment's last step's decision (N each; see TargetEnvState::last_step_transition):
  // transitions[i] = 1 where the match was not the continuation of the current clip, costs[i]
  // the match's squared distance to the query (normalized, weighted feature space). Training
  // reads this after every step for its cheap motion-quality log.
  void last_step_matches(uint8_t* transitions, float* costs) const {
    for (int i = 0; i < num_envs(); ++i) {
      transitions[i] = envs_[i].last_step_transition;
      costs[i] = envs_[i].last_step_cost;
    }
  }

 protected:
  // db and matcher are borrowed and must outlive the env. num_threads 0 = all cores.
  TargetVecEnv(const Database& db, const Matcher& matcher, int num_envs, const Config& config, int num_threads)
      : db_(db),
        matcher_(matcher),
        config_(config),
        envs_(static_cast<size_t>(num_envs)),
        pool_(num_threads) {
    target_env_check(db, matcher, num_envs, config);
    trajectory_action_box(db, config.action_limit_std, low_, high_);
    clip_filter_ = ClipCostFilter(db, config.clip_costs);
    request_code_ = RequestCode(db, config.request_groups);
    request_mix_ = mmrl::request_mix(db, request_code_, config.request_any);
    every_clip_ = select_request(db, TagRequest{});
    for (int i = 0; i < num_envs; ++i) envs_[i].rng = Rng(0, static_cast<uint64_t>(i));
  }

  // The autoreset loop (see the header comment). actions: N x kActionDim. after_step(i) runs
  // once per env after its step and before any reset (a task writes its extra outputs there).
  // grain: the smallest chunk of envs per thread.
  template <class AfterStep>
  void step_envs(const float* actions, const TargetStepBuffers& out, int64_t grain, AfterStep&& after_step) {
    pool_.parallel_for(num_envs(), [&](int64_t b, int64_t e, int) {
      for (int64_t i = b; i < e; ++i) {
        const int env = static_cast<int>(i);
        State& s = envs_[i];
        float* row = out.obs + i * task().obs_dim();
        if (s.autoreset_pending) {  // NEXT_STEP: this step is the reset; the action is ignored
          reset_env(env, row);
          s.last_step_frames = 0;
          s.last_step_transition = false;
          s.last_step_cost = 0;
          s.last_step_match = -1;
          s.last_step_transition_cost = 0;
          out.rewards[i] = 0;
          out.terminated[i] = out.truncated[i] = out.success[i] = 0;
          write_decision(s, out, i);
          after_step(env);
          continue;
        }
        TaskStep r = task().advance(env, actions + i * Task::kActionDim);
        r.reward -= config_.transition_pose_weight * s.last_pose_jump;
        if (s.last_transition) r.reward -= config_.transition_penalty;
        s.steps += 1;
        s.episode_return += r.reward;
        s.last_step_frames = r.frames_played;
        s.last_step_transition = s.last_transition;
        s.last_step_cost = s.last_cost;
        s.last_step_match = s.last_match;
        s.last_step_transition_cost = s.last_transition_cost;
        s.episode_frames += r.frames_played;
        s.stats.decisions += 1;
        s.stats.transitions += s.last_transition;
        s.stats.cost_sum += s.last_cost;
        s.stats.frames += r.frames_played;
        const bool truncated = !r.terminated && s.steps >= config_.max_steps;
        out.rewards[i] = r.reward;
        out.terminated[i] = r.terminated;
        out.truncated[i] = truncated;
        out.success[i] = r.success;
        write_decision(s, out, i);
        after_step(env);
        if (r.terminated || truncated) {
          float* final_row = out.final_obs + i * task().obs_dim();
          task().observe(env, final_row);
          out.episode_return[i] = static_cast<float>(s.episode_return);
          out.episode_length[i] = s.steps;
          if (out.episode_frames) out.episode_frames[i] = s.episode_frames;
          if (next_step_autoreset_) {
            std::copy(final_row, final_row + task().obs_dim(), row);
            s.autoreset_pending = true;
          } else {
            reset_env(env, row);
          }
        } else {
          task().observe(env, row);
        }
      }
    }, grain);
  }

  // The optional per-step rows of TargetStepBuffers.
  static void write_decision(const State& s, const TargetStepBuffers& out, int64_t i) {
    if (out.step_frames) out.step_frames[i] = s.last_step_frames;
    if (out.transitions) out.transitions[i] = s.last_step_transition;
    if (out.costs) out.costs[i] = s.last_step_cost;
  }

  // Draws env i's episode start (frame, root, target in the square of half_extent meters).
  void draw_start(int i, float half_extent) {
    State& s = envs_[i];
    draw_episode_start(s.rng, request(i), config_.random_heading, half_extent, config_.min_target_distance,
                       &s.frame, &s.root, &s.target_x, &s.target_z);
  }


  // Hook of set_state for tasks whose state depends on the root (a task hides it).
  void on_state_set(int) {}
  // Hook of set_compressed (a task hides it): after a model is set or cleared.
  void on_compressed_set() {}

  // The transition cost of env i's next match (a task hides it to make the bias depend on
  // its state): the config's transition_cost.
  float decision_transition_cost(int) const { return config_.transition_cost; }

  // The candidate filter of env i's next match (a task hides it to add its own rules): the
  // config's clip costs (decision.hpp's ClipCostFilter), or none.
  // Env i's request over them (RequestFilter) when it restricts the clips.
  const CandidateFilter* candidate_filter(int i) { return request_filter(i); }
  // The queries a compressed controller projects (shortlist_queries' fan; k is unused): the
  // query alone, unless a task's filter prices projections and wants its turned copies too.
  Shortlist compressed_shortlist() const { return {}; }
  // The base every task's filter builds on: env i's request (if it restricts the clips) over
  // the clip costs (if any).
  const CandidateFilter* request_filter(int i) {
    const RequestSelection& r = request(i);
    if (!r.restricts()) return clip_filter_.get();
    envs_[i].request_filter.set(db_, r.clip_mask.data(), clip_filter_.get());
    return &envs_[i].request_filter;
  }
  // The request code of env i (request_dim() floats) into out: all 0 without a request.
  void observe_request(int i, float* out) const {
    const State& s = envs_[i];
    const float* code = nullptr;
    if (s.request_pinned)
      code = s.pinned_code.data();
    else if (s.request_index >= 0)
      code = request_mix_.codes[static_cast<size_t>(s.request_index)].data();
    for (int k = 0; k < request_dim(); ++k) out[k] = code ? code[k] : 0.0f;
  }
  // How the filter's shortlist is drawn (decision.hpp's Shortlist; k = 0: no shortlist, the
  // filter runs in the exact search, the clip costs' rule). A task with a costly filter hides it.
  Shortlist candidate_shortlist() const { return {}; }

  // Distance (meters) from env i's root to its target.
  float target_distance(const State& s) const { return std::hypot(s.target_x - s.root.x, s.target_z - s.root.z); }

  // The goal g_t: the target in the character frame (meters), written to two floats.
  void observe_goal(const State& s, float* out) const {
    const Vec2 g = world_to_local_xz(s.target_x - s.root.x, s.target_z - s.root.z, s.root.yaw);
    out[0] = g.x();
    out[1] = g.y();
  }

  // c_t: the normalized pose features of env i's current frame (kPoseDim floats), or of its
  // compressed state.
  void observe_pose(const State& s, float* out) const {
    const float* pose = compressed_ ? s.cstate.data() : &db_.normalized[static_cast<size_t>(s.frame) * kFeatureDim];
    for (int k = 0; k < kPoseDim; ++k) out[k] = pose[k];
  }

  // Playback of decision j (decide's frame): the root delta of its k-th frame, and the end of
  // the step's playback (the current frame becomes j + frames_per_step, or the compressed
  // state moves to the played one).
  const float* played_delta(const State& s, int64_t j, int k) const {
    if (compressed_) return &s.crows[static_cast<size_t>(k) * compressed_->pose_dim() + 9 * compressed_->num_joints];
    return &db_.root_deltas[static_cast<size_t>(j + k) * 3];
  }
  void end_playback(State& s, int64_t j) {
    if (compressed_) {
      std::copy(s.cnext.begin(), s.cnext.end(), s.cstate.begin());  // end_compressed_playback's rule
      return;
    }
    s.frame = j + config_.frames_per_step;
  }
  // A task that plays compressed controllers says so (and reads played_delta, end_playback).
  static constexpr bool kPlaysCompressed = false;
  // Starts env s's compressed state from its database frame (nothing without a model).
  void start_compressed(State& s) {
    if (compressed_ == nullptr) return;
    const size_t S = static_cast<size_t>(compressed_->state_dim());
    const float* row = compressed_states_ + static_cast<size_t>(s.frame) * S;
    std::copy(row, row + S, s.cstate.begin());
  }

  const Database& db_;
  const Matcher& matcher_;
  Config config_;
  std::vector<State> envs_;
  float low_[kTrajectoryDim], high_[kTrajectoryDim];
  ClipCostFilter clip_filter_;
  RequestCode request_code_;
  RequestMix request_mix_;
  RequestSelection every_clip_;  // the request of an env without one: every clip
  const CompressedModel* compressed_ = nullptr;
  const float* compressed_states_ = nullptr;  // N x state_dim, per database frame
  bool next_step_autoreset_ = false;
  ThreadPool pool_;

 private:
  Task& task() { return static_cast<Task&>(*this); }
  const Task& task() const { return static_cast<const Task&>(*this); }
};

}  // namespace mmrl
