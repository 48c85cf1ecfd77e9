// The batched target-reaching environment, shared by every task (tasks/plane.hpp,
// tasks/obstacles.hpp, tasks/arrive.hpp), in two layers as envpool splits them:
//
// TargetTask<Task, Config, State> is the task of N characters, what one decision and one step
// need: the database and matcher (borrowed), the config, one state per character (its root,
// target, motion, decision, RNG and episode counters: target_env.hpp), the motion source, the
// decision engine (a Decider and each character's rule chain), requests, the episode starts
// (reset_env), and the step: it decides, plays the decision's frames, asks the task what each
// did and for its reward, and takes the decision's penalties off (play_step). The engine
// runtime holds a one-character TargetTask of its core (runtime_task.hpp) and nothing more.
//
// TargetVecEnv<Task> is the pool over a task, what training adds: a thread pool stepping the N
// environments in one call into caller-owned buffers (numpy arrays in Python), reseeding each
// environment's RNG from (seed, index) (results never depend on the thread count or on
// scheduling), counting each step (steps, truncation at max_steps, episode return, frames
// played, the decisions' statistics) and autoreset, in gymnasium's two modes. SAME_STEP (the default):
// an environment whose episode ended writes its last observation to final_obs, its return and
// length, and is reset at once, its first observation in obs. NEXT_STEP (what RLlib expects):
// the ending step writes the last observation to obs (and final_obs), and the env's next step
// ignores its action, resets it and returns the first observation with reward 0 and no flags.
// Each env draws its episodes from its own RNG, so both modes play the same episodes. Nothing
// is allocated per step.
//
// A task is a class Task deriving from TargetTask<Task, Config, State> (CRTP) that defines
//   Task(const Database&, const Matcher&, int num_envs, const Config&);
//   static constexpr int kObsDim, kActionDim;  (kObsDim: the base observation's size)
//   static constexpr bool kStepEndsAtEvent;    (a step stops at its first event; false: it plays
//                                               every frame, the paper's plane task)
//   int obs_dim() const;                       (this env's, >= kObsDim with optional segments)
//   ObsLayout task_obs_layout() const;         (its segments before the request code)
//   void observe(int i, float* obs_row) const;        // env i's observation now
//   void begin_episode(int i);                         // draws env i's episode (its RNG only)
//   FrameEvent played_frame(int i, const RootState& before);  // after each played frame
//   TaskStep end_step(int i, FrameEvent event);       // the step's reward and ending
// and nothing of the loop: the base decides, plays the decision's frames (play_step) and asks
// the task what each frame did. A task may hide begin_step(i, action) (after the decision,
// before any frame plays). Config derives from TaskConfig (tasks/task_config.hpp); State
// derives from TargetEnvState (target_env.hpp, with the step records and start rules). Its
// environment is TargetVecEnv<Task> (a subclass when the step writes outputs of its own).
//
// The motion: each character decides through one Decider (decider.hpp) over the task's motion
// source, the database (database_source.hpp) or another one set by set_source
// (compressed_source.hpp's); a task reads what it needs of the motion through source() and the
// decision record, never asking which source it has.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

#include <memory>
#include <type_traits>

#include "mmrl/database_source.hpp"
#include "mmrl/rules.hpp"
#include "mmrl/target_env.hpp"
#include "mmrl/threadpool.hpp"

namespace mmrl {

// The task of N characters (see the header comment): everything a decision and a step need,
// nothing of training's pool. Task: the CRTP task class.
template <class Task, class Config, class State>
class TargetTask {
 public:
  using ConfigType = Config;
  using StateType = State;
  int num_envs() const { return static_cast<int>(envs_.size()); }
  const Config& config() const { return config_; }
  const Database& database() const { return db_; }
  const float* action_low() const { return decider_.action_low(); }
  const float* action_high() const { return decider_.action_high(); }
  // The motion source every env plays now (the database, or set_source's).
  const MotionSource& source() const { return *source_; }
  State& state(int i) { return envs_[i]; }
  const State& state(int i) const { return envs_[i]; }

  // Resets environment i from its own RNG stream; writes its observation row (if not null).
  void reset_env(int i, float* obs_row) {
    State& s = envs_[i];
    if (!s.request_pinned && !request_mix_.empty())  // the episode's request, before its start is drawn
      s.request_index = static_cast<int>(request_mix_.pick(s.rng.uniform()));
    task().begin_episode(i);
    source_->start(s, s.frame);
    s.autoreset_pending = false;
    s.episode_frames = 0;
    s.steps = 0;
    s.episode_return = 0;
    s.decision = Decision{};
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

  // The observation's segments (target_env.hpp's ObsLayout): the task's own (obs_layout_of),
  // then the request code when the config has request_groups.
  ObsLayout obs_layout() const {
    ObsLayout layout = task().task_obs_layout();
    if (request_dim() > 0) layout.push_back({"request", request_dim(), "task.request_groups give a request code of " + std::to_string(request_dim())});
    return layout;
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

  // Another motion source for every env (e.g. compressed_source.hpp's compressed controller)
  // instead of the database, over this env's database and alive while set: decisions and
  // playback go through it. Every env restarts its motion on its frame now; episode starts still
  // draw database frames (the source starts from them). nullptr: back to the database.
  void set_source(std::shared_ptr<const MotionSource> source) {
    other_source_ = std::move(source);
    use_source(other_source_ ? *other_source_ : database_source_);
  }
  // Env i's motion (the source's state buffers), for the bindings.
  const MotionState& motion(int i) const { return envs_[i]; }
  // Moves env i to the end of its last decision's playback: what a step does after deciding,
  // for a caller that only decides (the engine runtime, whose character plays).
  void end_playback(int i) { source_->end_playback(envs_[i], envs_[i].decision, config_.frames_per_step); }
  // Sets what env i shows from the source's state (MotionSource::set_state; source().state_dim()
  // floats, finite; std::invalid_argument otherwise).
  void set_motion_state(int i, const float* state) { source_->set_state(envs_[i], state); }
  // Replaces the action box (12 + 12 normalized floats, low <= high): a controller file whose
  // database holds only its start frames carries the training database's box.
  void set_action_box(const float* low, const float* high) { decider_.set_action_box(low, high); }

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
  // With a source that has states (MotionSource::state_dim), frame -1 keeps env i's state (a database frame
  // starts from that frame's state).
  void set_state(int i, int64_t frame, float x, float z, float yaw) {
    if (!source_->starts_at(frame)) throw std::invalid_argument("frame is outside the database");
    if (!std::isfinite(x) || !std::isfinite(z) || !std::isfinite(yaw))
      throw std::invalid_argument("root must be finite");
    State& s = envs_[i];
    source_->start(s, frame);
    s.root.x = x;
    s.root.z = z;
    s.root.yaw = wrap_angle(yaw);
    task().on_state_set(i);
  }

  // The decision of env i now for `action` (12 normalized floats, finite): the Decider with
  // the task's rules (decision_rules: its transition cost, candidate filters and shortlists).
  // Records it as env i's decision (with the playback its source prepares); changes
  // nothing else. play_step calls it first; the engine runtime calls it on its one-character
  // task to decide as training did. Returns the database frame to play from (-1 for a candidate without a row).
  int64_t decide(int i, const float* action) {
    State& s = envs_[i];
    float query[kTrajectoryDim];
    const float* asked = task().decision_action(i, action, query);  // first: it may change what the rules read
    s.decision = decider_.decide(*source_, s, asked, decision_rules(i));
    task().keep_anchor(i, s.decision.anchor);
    return s.decision.match;
  }
  // Env i's rules for its next decision (what decide uses).
  DecisionRules decision_rules(int i) {
    DecisionRules rules;
    rules.transition_cost = task().decision_transition_cost(i);
    rules.anchor = task().anchors(i);
    rules_[static_cast<size_t>(i)].prepare(
        RuleContext{*source_, envs_[i], request(i), task().scene(i), task().standing(i), task().stand_turn(i)}, rules);
    return rules;
  }

 protected:
  // db and matcher are borrowed and must outlive the task.
  TargetTask(const Database& db, const Matcher& matcher, int num_envs, const Config& config)
      : db_(db),
        matcher_(matcher),
        config_(config),
        envs_(static_cast<size_t>(num_envs)) {
    check_options(config);  // every option against its range (task_config.hpp), then the cross-field rules
    target_env_check(db, matcher, num_envs, config);
    database_source_ = DatabaseSource(db, matcher);
    source_ = &database_source_;
    decider_ = Decider(db, config.action_limit_std);
    rules_.reserve(envs_.size());
    for (size_t i = 0; i < envs_.size(); ++i) rules_.emplace_back(RuleSetup{db, matcher, config_});
    request_code_ = RequestCode(db, config.request_groups);
    request_mix_ = mmrl::request_mix(db, request_code_, config.request_any);
    every_clip_ = select_request(db, TagRequest{});
    for (int i = 0; i < num_envs; ++i) envs_[i].rng = Rng(0, static_cast<uint64_t>(i));
  }

  // One RL step of env i, no autoreset: the decision for `action`, then its frames played one
  // by one, the task told of each (played_frame, with the root before it); the first event sets
  // the step's frames played, and ends the step when the task says so (kStepEndsAtEvent). The
  // reward is the task's (end_step) minus what every task pays for its decision
  // (task_config.hpp): transition_pose_weight times the pose jump, and transition_penalty for a
  // transition.
  TaskStep play_step(int i, const float* action) {
    State& s = envs_[i];
    decide(i, action);
    root_shift(s.root, s.decision.anchor);
    task().begin_step(i, action);
    FrameEvent event = FrameEvent::kNone;
    int frames = config_.frames_per_step;
    for (int k = 0; k < config_.frames_per_step; ++k) {
      const RootState before = s.root;
      root_advance(s.root, played_delta(s, k));
      const FrameEvent e = task().played_frame(i, before);
      if (e == FrameEvent::kNone || event != FrameEvent::kNone) continue;
      event = e;
      frames = k + 1;
      if constexpr (Task::kStepEndsAtEvent) break;
    }
    end_playback(s);
    TaskStep out = task().end_step(i, event);
    out.reward -= config_.transition_pose_weight * s.decision.pose_jump;
    if (s.decision.transition) out.reward -= config_.transition_penalty;
    out.step_frames = frames;
    return out;
  }

  // Draws env i's episode start (frame, root, target in the square of half_extent meters).
  void draw_start(int i, float half_extent) {
    State& s = envs_[i];
    draw_episode_start(s.rng, request(i), config_.random_heading, half_extent, config_.min_target_distance,
                       &s.frame, &s.root, &s.target_x, &s.target_z);
  }


  // Hook of play_step after the decision, before any frame plays (a task hides it).
  void begin_step(int, const float*) {}
  // Hook of set_state for tasks whose state depends on the root (a task hides it).
  void on_state_set(int) {}
  // Hook of set_source (a task hides it): after the source changed.
  void on_source_set() {}

  // The trajectory env i's next match asks for (a task hides it to take over the action in
  // some state, writing its own into `scratch`, kTrajectoryDim floats): the action.
  const float* decision_action(int, const float* action, float*) const { return action; }
  // The transition cost of env i's next match (a task hides it to make the bias depend on
  // its state): the config's transition_cost.
  float decision_transition_cost(int) const { return config_.transition_cost; }

  // The obstacles env i's rules may read at its next decision (a task with obstacles hides it):
  // none.
  const ObstacleScene* scene(int) { return nullptr; }
  // Whether env i's next decision asks the character to stand still (a task that stands hides
  // it; read after decision_action): no.
  bool standing(int) const { return false; }
  // Whether env i's next transition keeps the planted feet in place (DecisionRules::anchor): no.
  bool anchors(int) const { return false; }
  // May cancel the anchor of env i's decision (sets it to (0, 0)): keeps it.
  void keep_anchor(int, float*) const {}
  // While standing, the turn left to the facing it stands with (radians): none.
  float stand_turn(int) const { return 0.0f; }
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

  // Distance (meters) from env i's root to its target.
  float target_distance(const State& s) const { return std::hypot(s.target_x - s.root.x, s.target_z - s.root.z); }
  // Whether env i's root is within success_radius of its target (tested on every played frame).
  bool within_success_radius(const State& s) const {
    const float dx = s.target_x - s.root.x, dz = s.target_z - s.root.z;
    return dx * dx + dz * dz <= config_.success_radius * config_.success_radius;
  }

  // The goal g_t: the target in the character frame (meters), written to two floats.
  void observe_goal(const State& s, float* out) const {
    const Vec2 g = world_to_local_xz(s.target_x - s.root.x, s.target_z - s.root.z, s.root.yaw);
    out[0] = g.x();
    out[1] = g.y();
  }

  // c_t: the normalized pose features of what env i shows now (kPoseDim floats).
  void observe_pose(const State& s, float* out) const {
    const float* pose = source_->current(s).features;
    for (int k = 0; k < kPoseDim; ++k) out[k] = pose[k];
  }

  // Playback of env s's decision: the root delta of its k-th frame, and the end of the step's
  // playback (the source moves on).
  const float* played_delta(const State& s, int k) const { return source_->played_delta(s, s.decision, k); }
  void end_playback(State& s) { source_->end_playback(s, s.decision, config_.frames_per_step); }
  // Switches every env to `source` (prepared, and started on its frame) and tells the task.
  void use_source(const MotionSource& source) {
    source_ = &source;
    for (State& s : envs_) {
      source.prepare(s, config_.frames_per_step);
      source.start(s, s.frame);
    }
    task().on_source_set();
  }

  const Database& db_;
  const Matcher& matcher_;
  Config config_;
  std::vector<State> envs_;
  DatabaseSource database_source_;
  std::shared_ptr<const MotionSource> other_source_;  // set_source's, or null: the database
  const MotionSource* source_ = nullptr;
  Decider decider_;
  std::vector<RuleChain> rules_;  // per env, rules.hpp's registered ones that are on
  RequestCode request_code_;
  RequestMix request_mix_;
  RequestSelection every_clip_;  // the request of an env without one: every clip

 private:
  Task& task() { return static_cast<Task&>(*this); }
  const Task& task() const { return static_cast<const Task&>(*this); }
};


// The pool over a task (see the header comment): threads, per-env RNGs, bookkeeping and
// autoreset. Task: a TargetTask subclass.
template <class Task>
class TargetVecEnv : public Task {
  static_assert(std::is_base_of<TargetTask<Task, typename Task::ConfigType, typename Task::StateType>, Task>::value,
                "TargetVecEnv<Task>: Task must derive from TargetTask<Task, Config, State>");

 public:
  // db and matcher are borrowed and must outlive the env. num_threads 0 = all cores.
  // Throws std::invalid_argument on a bad config.
  TargetVecEnv(const Database& db, const Matcher& matcher, int num_envs, const typename Task::ConfigType& config,
               int num_threads = 0)
      : Task(db, matcher, num_envs, config), pool_(num_threads) {}

  // Autoreset mode (see the header comment): false = SAME_STEP, true = NEXT_STEP. Switching
  // applies from the next step; an env whose reset is pending still gets it.
  void set_autoreset_next_step(bool on) { next_step_autoreset_ = on; }
  bool autoreset_next_step() const { return next_step_autoreset_; }

  // Reseeds every environment's RNG from (seed, index) and resets all; obs: N x obs_dim() (or null).
  void reset(uint64_t seed, float* obs) {
    for (int i = 0; i < this->num_envs(); ++i) {
      this->envs_[i].rng = Rng(seed, static_cast<uint64_t>(i));
      this->envs_[i].step_frames = 0;
      this->envs_[i].last_step = Decision{};
    }
    pool_.parallel_for(this->num_envs(), [&](int64_t b, int64_t e, int) {
      for (int64_t i = b; i < e; ++i) this->reset_env(static_cast<int>(i), obs ? obs + i * this->obs_dim() : nullptr);
    });
  }

  // Every env's MatchStats since the last call, summed; zeroes them.
  MatchStats pop_match_stats() {
    MatchStats total;
    for (auto& s : this->envs_) {
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
    for (int i = 0; i < this->num_envs(); ++i) out[i] = this->envs_[i].frame;
  }
  // Each environment's frames played in the last step (N; see TargetEnvState::step_frames).
  void step_frames(int32_t* out) const {
    for (int i = 0; i < this->num_envs(); ++i) out[i] = this->envs_[i].step_frames;
  }
  // Each environment's last step's decision (N each; see TargetEnvState::last_step):
  // transitions[i] = 1 where the match was not the continuation of the current clip, costs[i]
  // the match's squared distance to the query (normalized, weighted feature space). Training
  // reads this after every step for its cheap motion-quality log.
  void last_step_transitions(uint8_t* transitions, float* costs) const {
    for (int i = 0; i < this->num_envs(); ++i) {
      transitions[i] = this->envs_[i].last_step.transition;
      costs[i] = this->envs_[i].last_step.cost;
    }
  }

 protected:
  // The autoreset loop (see the header comment). actions: N x kActionDim. after_step(i) runs
  // once per env after its step and before any reset (a task writes its extra outputs there).
  // grain: the smallest chunk of envs per thread.
  template <class AfterStep>
  void step_envs(const float* actions, const TargetStepBuffers& out, int64_t grain, AfterStep&& after_step) {
    pool_.parallel_for(this->num_envs(), [&](int64_t b, int64_t e, int) {
      for (int64_t i = b; i < e; ++i) {
        const int env = static_cast<int>(i);
        typename Task::StateType& s = this->envs_[i];
        float* row = out.obs + i * this->obs_dim();
        if (s.autoreset_pending) {  // NEXT_STEP: this step is the reset; the action is ignored
          this->reset_env(env, row);
          s.step_frames = 0;
          s.last_step = Decision{};
          out.rewards[i] = 0;
          out.terminated[i] = out.truncated[i] = out.success[i] = 0;
          write_decision(s, out, i);
          after_step(env);
          continue;
        }
        const TaskStep r = this->play_step(env, actions + i * Task::kActionDim);
        s.steps += 1;
        s.episode_return += r.reward;
        s.step_frames = r.step_frames;
        s.last_step = s.decision;
        s.episode_frames += r.step_frames;
        s.stats.decisions += 1;
        s.stats.transitions += s.decision.transition;
        s.stats.cost_sum += s.decision.cost;
        s.stats.frames += r.step_frames;
        const bool truncated = !r.terminated && s.steps >= this->config_.max_steps;
        out.rewards[i] = r.reward;
        out.terminated[i] = r.terminated;
        out.truncated[i] = truncated;
        out.success[i] = r.success;
        write_decision(s, out, i);
        after_step(env);
        if (r.terminated || truncated) {
          float* final_row = out.final_obs + i * this->obs_dim();
          this->observe(env, final_row);
          out.episode_return[i] = static_cast<float>(s.episode_return);
          out.episode_length[i] = s.steps;
          if (out.episode_frames) out.episode_frames[i] = s.episode_frames;
          if (next_step_autoreset_) {
            std::copy(final_row, final_row + this->obs_dim(), row);
            s.autoreset_pending = true;
          } else {
            this->reset_env(env, row);
          }
        } else {
          this->observe(env, row);
        }
      }
    }, grain);
  }

  // The optional per-step rows of TargetStepBuffers.
  static void write_decision(const typename Task::StateType& s, const TargetStepBuffers& out, int64_t i) {
    if (out.step_frames) out.step_frames[i] = s.step_frames;
    if (out.transitions) out.transitions[i] = s.last_step.transition;
    if (out.costs) out.costs[i] = s.last_step.cost;
  }

  bool next_step_autoreset_ = false;
  ThreadPool pool_;
};

}  // namespace mmrl
