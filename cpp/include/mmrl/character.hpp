// A motion-matching character: plays decisions (decider.hpp's Decider makes them; a motion
// source hands each one over as PlayedFrames) as root motion and, on the full path,
// world-space poses with inertialization, foot locking and leg IK. It never decides: the root
// motion is exactly decision.hpp's playback (root_advance over the played frames' deltas), so
// the fast path and the full path follow the same root trajectory for the same decisions.
//
// Poses. The database frame f is stored in the database's world, where its character frame
// is C_f = (root_positions[f], root_yaws[f]); the character is at the world root
// W = (x, z, yaw). A played frame is placed by the rigid map W * C_f^-1:
//   - each BVH root joint (parent -1) has its local transform mapped by W * C_f^-1 (for
//     Bandai the root is a static dummy and the hips move below it: the general case);
//   - the hips are blended in the character frame (stitch.hpp) and placed at W, then
//     re-expressed below their parent, so exported BVH local transforms stay consistent;
//   - the other joints keep their (inertialized) local rotations and database translations.
// Timing: after the k-th root advance of a step the root belongs to frame j + k, the k-th
// played frame. At a transition from the shown frame s to the match j, the source pose is s
// and the destination is j (the same instant); the first shown frame is j + 1.
//
// Foot locking (world space, per side): when the played frame's database contact starts
// the ankle is locked at once where it is shown (so a locked foot does not move, and
// locking never jumps); the lock is released when the contact ends or the animated ankle is
// more than lock_release_distance from it (then it stays free until the next contact), and
// a weight blends the IK target back to the animated ankle over lock_blend_time. The
// two-bone IK (ik.hpp) moves the ankle to the target and the foot keeps its animated world
// orientation.
//
// Where the frames come from. Playback shows FramePoses: a frame's pose in its own character
// frame. A motion source's PlayedFrames makes them (the database's from its frames,
// database_source.hpp; a compressed controller's from the rows its networks decode,
// compressed_source.hpp); the character never asks which: the same inertialization, foot
// locking and IK for both.
//
// The step allocates nothing: every buffer is sized at construction.
#pragma once

#include <cstdint>
#include <vector>

#include "mmrl/decision.hpp"
#include "mmrl/ik.hpp"
#include "mmrl/stitch.hpp"

namespace mmrl {

struct CharacterOptions {
  int frames_per_step = 6;               // frames played per step (1..30)
  bool poses = true;                     // false: the fast path (root motion only)
  float inertialization_halflife = 0.1f; // seconds; <= 0: hard switch
  bool ik = true;                        // two-bone leg IK
  bool foot_locking = true;              // lock planted feet (needs ik)
  float ik_margin = 0.0f;                // meters short of a straight leg
  float lock_release_distance = 0.5f;    // meters between locked and animated ankle
  float lock_blend_time = 0.2f;          // seconds to blend a lock out (locking is immediate)
};

// One frame's pose in its own character frame C_f: what playback shows.
struct FramePose {
  std::vector<Quat> rotations;      // J local rotations; a root joint's (parent -1) relative to C_f
  std::vector<Vec3> translations;   // J local translations (meters); a root joint's in C_f
  float root_delta[3] = {0, 0, 0};  // C_f's motion to the next frame: dx, dz in C_f, dyaw
  uint8_t contacts[2] = {0, 0};     // left, right foot planted
  void resize(int num_joints) {
    rotations.assign(num_joints, Quat::Identity());
    translations.assign(num_joints, Vec3::Zero());
  }
};

// Database frame f as a FramePose (sized to the database's joints).
void database_frame_pose(const Database& db, int64_t frame, FramePose& out);

// The frames of one decision, as a motion source hands them to a character: frame 0 is the
// chosen frame (the transition's destination), frames 1..F are shown. Each source implements it
// in its own file.
class PlayedFrames {
 public:
  virtual ~PlayedFrames() = default;
  // The database frame that frame k is, or -1 (the character's frame() once it shows it).
  virtual int64_t frame(int k) const = 0;
  // Frame k's pose in its own character frame (out is sized to the character's joints).
  virtual void pose(int k, FramePose& out) const = 0;
  // The root's motion from frame k to frame k + 1: dx, dz in frame k's character frame, dyaw.
  virtual const float* root_delta(int k) const = 0;
  // Frame k's foot contacts (left, right; 1 planted).
  virtual void contacts(int k, uint8_t out[2]) const = 0;
  // Two poses one frame apart whose difference is frame k's velocity (a, then b): a later
  // transition from frame k blends from this velocity. before: the pose shown before frame k
  // (k > 0).
  virtual void velocity_pair(int k, const FramePose& before, FramePose& a, FramePose& b) const = 0;
};

// Global positions (J x 3, meters) of database frame f in the database's world.
// rotations_scratch: J x 4 floats of caller-owned scratch (the global rotations on return).
void database_pose_global(const Database& db, int64_t frame, float* positions, float* rotations_scratch);

class Character {
 public:
  // db is borrowed and must outlive the character.
  Character(const Database& db, const CharacterOptions& options);

  const CharacterOptions& options() const { return options_; }
  const Database& database() const { return db_; }
  int num_joints() const { return J_; }

  // Shows frame 0 of `frames` at the world root (frame() becomes frames.frame(0)); clears
  // offsets and locks, and computes the shown pose.
  void show(const PlayedFrames& frames, const RootState& root);
  // Plays a decision (a Decider's: the batched env's, so the full path never decides again):
  // frames 1..F shown, the root advanced by frames 0..F-1's root deltas. transition: frame 0
  // replaces what played so far, inertialized from the pose shown now (with its velocity) to
  // frame 0 (with its velocity from frames 0 and 1). cost is what last_cost reports. anchor
  // (a transition's Decision::anchor, or null): the root first moves by it and the blend starts
  // from the pose shown now moved back by as much, so the body does not jump and the planted
  // feet stay where they stand while the blend brings the body over them.
  void play(const PlayedFrames& frames, bool transition, float cost, const float* anchor = nullptr);

  const RootState& root() const { return root_; }
  int64_t frame() const { return frame_; }
  int64_t last_match() const { return last_match_; }
  bool last_transition() const { return last_transition_; }
  float last_cost() const { return last_cost_; }

  // Per played frame of the last step (frames_per_step rows). Pose arrays are filled only
  // on the full path.
  const int64_t* played_frames() const { return played_.data(); }        // F
  const float* roots() const { return roots_.data(); }                    // F x 3 (x, z, yaw)
  const float* global_positions() const { return gpos_.data(); }         // F x J x 3, meters
  const float* global_rotations() const { return grot_.data(); }         // F x J x 4, w x y z
  const float* local_translations() const { return lpos_.data(); }       // F x J x 3 (BVH locals)
  const float* local_rotations() const { return lrot_.data(); }          // F x J x 4
  const uint8_t* contacts() const { return contacts_.data(); }           // F x 2, database contacts
  const float* lock_weights() const { return lock_w_out_.data(); }       // F x 2, 0..1
  // The left and right ankles (roles foot) before foot locking and IK: F x 2 x 3, world meters.
  // IK changes nothing else and nothing later (decisions, inertialization and the next frames
  // do not depend on it), so these are exactly the ankles of the same run with IK off: one run
  // measures foot sliding with IK on and off over the same frames.
  const float* animated_feet() const { return anim_feet_.data(); }
  // The pose shown now (the last played frame, or the reset frame): J x 3 / J x 4.
  const float* current_global_positions() const { return cur_gpos_.data(); }
  const float* current_global_rotations() const { return cur_grot_.data(); }
  const float* current_local_translations() const { return cur_lpos_.data(); }
  const float* current_local_rotations() const { return cur_lrot_.data(); }
  const float* current_animated_feet() const { return cur_anim_feet_; }  // 2 x 3, see animated_feet
  const float* current_lock_weights() const { return cur_lock_w_; }      // 2, see lock_weights

 private:
  void blend_pose_of(const FramePose& frame, BlendPose& pose) const;
  // Velocities from frame a to the next frame b (1/fps apart).
  void blend_velocity(const FramePose& a, const FramePose& b, BlendVelocity& vel);
  // Shows a frame (root_ already advanced to it): fills the current pose.
  void show_frame(const FramePose& frame, bool decay);
  void lock_feet(const FramePose& frame, bool decay);
  // The step outputs of the k-th frame shown.
  void record_step_frame(int k, int64_t frame, const uint8_t* contacts);
  void forward_kinematics_joint(int j);
  void forward_kinematics();
  void solve_leg(int side, const Vec3& target);

  const Database& db_;
  CharacterOptions options_;
  int J_ = 0;
  float dt_ = 1.0f / 30.0f;
  std::vector<int> hips_chain_;   // root .. hips
  std::vector<bool> above_hips_;  // ancestors of the hips

  RootState root_;
  int64_t frame_ = 0, last_match_ = -1;
  bool last_transition_ = false;
  float last_cost_ = 0;

  Inertializer inertializer_;
  BlendPose src_, dst_, anim_, shown_, scratch_;
  FramePose fp_a_, fp_b_;                // scratch frames
  FramePose fp_shown_;                   // the frame shown now (a transition's source pose)
  FramePose fp_before_;                  // the frame shown before it (during a step)
  FramePose vel_a_, vel_b_;              // its velocity pair (PlayedFrames::velocity_pair)
  BlendVelocity src_vel_, dst_vel_;

  // Foot locks.
  bool locked_[2] = {false, false}, released_in_contact_[2] = {false, false};
  float lock_weight_[2] = {0, 0};
  Vec3 lock_position_[2] = {Vec3::Zero(), Vec3::Zero()};

  // Current pose: BVH-form locals (roots placed in the world) and globals.
  std::vector<Vec3> loc_t_, glob_t_;
  std::vector<Quat> loc_r_, glob_r_;
  std::vector<float> cur_gpos_, cur_grot_, cur_lpos_, cur_lrot_;
  float cur_anim_feet_[6] = {0, 0, 0, 0, 0, 0};
  float cur_lock_w_[2] = {0, 0};  // lock weights of the pose shown now

  // Step outputs.
  std::vector<int64_t> played_;
  std::vector<float> roots_, gpos_, grot_, lpos_, lrot_, lock_w_out_, anim_feet_;
  std::vector<uint8_t> contacts_;
};

}  // namespace mmrl
