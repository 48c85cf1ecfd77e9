#include "mmrl/character.hpp"

#include "mmrl/database_source.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace mmrl {

namespace {

inline Vec3 load3(const float* p) { return Vec3(p[0], p[1], p[2]); }
inline void store3(const Vec3& v, float* p) {
  p[0] = v.x();
  p[1] = v.y();
  p[2] = v.z();
}
inline float smoothstep(float x) { return x * x * (3.0f - 2.0f * x); }

}  // namespace

void database_frame_pose(const Database& db, int64_t f, FramePose& out) {
  const int J = db.num_joints;
  if (static_cast<int>(out.rotations.size()) != J) out.resize(J);
  const size_t o = static_cast<size_t>(f) * J;
  const float yaw = db.root_yaws[f];
  const Quat to_local = quat_from_yaw(-yaw);
  const Vec3 c = load3(&db.root_positions[f * 3]);
  for (int j = 0; j < J; ++j) {
    const Quat r = quat_load(&db.bone_rotations[(o + j) * 4]);
    const Vec3 t = load3(&db.bone_translations[(o + j) * 3]);
    if (db.skeleton.parents[j] < 0) {
      out.rotations[j] = (to_local * r).normalized();
      out.translations[j] = world_to_local_dir(t - c, yaw);
    } else {
      out.rotations[j] = r;
      out.translations[j] = t;
    }
  }
  for (int k = 0; k < 3; ++k) out.root_delta[k] = db.root_deltas[static_cast<size_t>(f) * 3 + k];
  out.contacts[0] = db.contacts[static_cast<size_t>(f) * 2];
  out.contacts[1] = db.contacts[static_cast<size_t>(f) * 2 + 1];
}

void database_pose_global(const Database& db, int64_t frame, float* positions, float* rotations_scratch) {
  const size_t o = static_cast<size_t>(frame) * db.num_joints;
  pose_forward_kinematics(db.skeleton.parents, &db.bone_translations[o * 3], &db.bone_rotations[o * 4], positions,
                          rotations_scratch);
}

Character::Character(const Database& db, const CharacterOptions& options)
    : db_(db), options_(options), J_(db.num_joints) {
  check_frames_per_step(options.frames_per_step);
  if (!std::isfinite(options.inertialization_halflife))
    throw std::invalid_argument("inertialization_halflife must be finite (<= 0 turns it off)");
  if (!(options.ik_margin >= 0) || !(options.lock_release_distance > 0) || !(options.lock_blend_time >= 0))
    throw std::invalid_argument("ik_margin must be >= 0, lock_release_distance > 0 and lock_blend_time >= 0");
  if (db.contacts.size() != static_cast<size_t>(db.num_frames) * 2)
    throw std::invalid_argument("database has no foot contacts (rebuild it)");
  dt_ = 1.0f / db.fps;
  above_hips_.assign(J_, false);
  for (int a = db.roles.hips; a >= 0; a = db.skeleton.parents[a]) hips_chain_.insert(hips_chain_.begin(), a);
  for (int a : hips_chain_)
    if (a != db.roles.hips) above_hips_[a] = true;
  std::vector<bool> blended(J_);
  for (int j = 0; j < J_; ++j) blended[j] = !above_hips_[j];
  inertializer_.reset(J_, db.roles.hips, blended, options.inertialization_halflife);
  for (BlendPose* p : {&src_, &dst_, &anim_, &shown_, &scratch_}) p->resize(J_);
  for (FramePose* p : {&fp_a_, &fp_b_, &fp_shown_, &fp_before_, &vel_a_, &vel_b_}) p->resize(J_);
  src_vel_.resize(J_);
  dst_vel_.resize(J_);
  loc_t_.assign(J_, Vec3::Zero());
  glob_t_.assign(J_, Vec3::Zero());
  loc_r_.assign(J_, Quat::Identity());
  glob_r_.assign(J_, Quat::Identity());
  cur_gpos_.assign(static_cast<size_t>(J_) * 3, 0);
  cur_lpos_.assign(static_cast<size_t>(J_) * 3, 0);
  cur_grot_.assign(static_cast<size_t>(J_) * 4, 0);
  cur_lrot_.assign(static_cast<size_t>(J_) * 4, 0);
  const size_t F = options.frames_per_step;
  played_.assign(F, 0);
  roots_.assign(F * 3, 0);
  contacts_.assign(F * 2, 0);
  lock_w_out_.assign(F * 2, 0);
  if (options.poses) {
    gpos_.assign(F * J_ * 3, 0);
    lpos_.assign(F * J_ * 3, 0);
    grot_.assign(F * J_ * 4, 0);
    lrot_.assign(F * J_ * 4, 0);
    anim_feet_.assign(F * 2 * 3, 0);
  }
  show_database_frame(*this, db, 0, RootState{});  // until a source shows its start (out_of_range: no frames)
}

void Character::show(const PlayedFrames& frames, const RootState& root) {
  frame_ = frames.frame(0);
  root_ = root;
  last_match_ = -1;
  last_transition_ = false;
  inertializer_.clear();
  for (int s = 0; s < 2; ++s) {
    locked_[s] = released_in_contact_[s] = false;
    lock_weight_[s] = 0;
  }
  if (!options_.poses) return;
  frames.pose(0, fp_shown_);
  if (inertializer_.enabled()) frames.velocity_pair(0, fp_shown_, vel_a_, vel_b_);
  show_frame(fp_shown_, false);
}

void Character::blend_pose_of(const FramePose& fp, BlendPose& pose) const {
  for (int j = 0; j < J_; ++j) pose.rotations[j] = fp.rotations[j];
  // The hips' transform in the frame's character frame (the roots are given in it).
  Vec3 gp = Vec3::Zero();
  Quat gr = Quat::Identity();
  for (int a : hips_chain_) {
    gp = gp + gr * fp.translations[a];
    gr = gr * fp.rotations[a];
  }
  pose.hips_position = gp;
  pose.hips_rotation = gr.normalized();
}

void Character::blend_velocity(const FramePose& a, const FramePose& b, BlendVelocity& vel) {
  blend_pose_of(a, scratch_);
  // dst_/src_ may be in use by the caller; use anim_ as the second scratch.
  blend_pose_of(b, anim_);
  const float fps = db_.fps;
  for (int j = 0; j < J_; ++j)
    vel.angular[j] = quat_to_rotation_vector(anim_.rotations[j] * scratch_.rotations[j].conjugate()) * fps;
  vel.hips_angular = quat_to_rotation_vector(anim_.hips_rotation * scratch_.hips_rotation.conjugate()) * fps;
  vel.hips_linear = (anim_.hips_position - scratch_.hips_position) * fps;
}

void Character::forward_kinematics_joint(int j) {
  const int p = db_.skeleton.parents[j];
  if (p < 0) {
    glob_t_[j] = loc_t_[j];
    glob_r_[j] = loc_r_[j];
  } else {
    glob_t_[j] = glob_t_[p] + glob_r_[p] * loc_t_[j];
    glob_r_[j] = (glob_r_[p] * loc_r_[j]).normalized();
  }
}

void Character::forward_kinematics() {
  for (int j = 0; j < J_; ++j) forward_kinematics_joint(j);
}

void Character::solve_leg(int side, const Vec3& target) {
  const int up = db_.roles.upper_leg[side], lo = db_.roles.lower_leg[side], ft = db_.roles.foot[side];
  IkTwoBoneJob job;
  job.hip = glob_t_[up];
  job.knee = glob_t_[lo];
  job.ankle = glob_t_[ft];
  job.target = target;
  job.margin = options_.ik_margin;
  job.fallback_bend_direction = forward_from_yaw(root_.yaw);
  if (!job.Run()) return;
  // New globals of the thigh and shin; the foot keeps its world orientation.
  const Quat foot_global = glob_r_[ft];
  const Quat up_global = (job.hip_correction * glob_r_[up]).normalized();
  const Quat lo_global = (job.knee_correction * glob_r_[lo]).normalized();
  const int up_parent = db_.skeleton.parents[up];
  const Quat parent_global = up_parent >= 0 ? glob_r_[up_parent] : Quat::Identity();
  // Locals along the chain (upper -> lower -> foot are parent -> child in every skeleton
  // the roles accept, possibly with joints in between that keep their local rotations).
  loc_r_[up] = (parent_global.conjugate() * up_global).normalized();
  forward_kinematics();
  const int lo_parent = db_.skeleton.parents[lo];
  loc_r_[lo] = (glob_r_[lo_parent].conjugate() * lo_global).normalized();
  forward_kinematics();
  const int ft_parent = db_.skeleton.parents[ft];
  loc_r_[ft] = (glob_r_[ft_parent].conjugate() * foot_global).normalized();
  forward_kinematics();
}

void Character::show_frame(const FramePose& fp, bool decay) {
  blend_pose_of(fp, anim_);
  if (decay) {
    inertializer_.update(dt_, anim_, shown_);
  } else {
    shown_ = anim_;
  }
  // World placement: the root joints and the hips (given in the character frame) by W.
  const Quat world_yaw = quat_from_yaw(root_.yaw);
  const Vec3 world_origin(root_.x, 0.0f, root_.z);
  const auto& parents = db_.skeleton.parents;
  const int hips = db_.roles.hips;
  for (int j = 0; j < J_; ++j) {
    const int p = parents[j];
    if (j == hips) {
      const Vec3 gp = world_origin + world_yaw * shown_.hips_position;
      const Quat gr = (world_yaw * shown_.hips_rotation).normalized();
      if (p < 0) {
        loc_t_[j] = gp;
        loc_r_[j] = gr;
      } else {
        loc_r_[j] = (glob_r_[p].conjugate() * gr).normalized();
        loc_t_[j] = glob_r_[p].conjugate() * (gp - glob_t_[p]);
      }
    } else if (p < 0) {
      loc_t_[j] = world_origin + world_yaw * fp.translations[j];
      loc_r_[j] = (world_yaw * shown_.rotations[j]).normalized();
    } else {
      loc_t_[j] = fp.translations[j];
      loc_r_[j] = shown_.rotations[j];
    }
    forward_kinematics_joint(j);  // the hips' local transform above needs its parent's global
  }

  // The ankles before locking and IK (solve_leg of one side leaves the other ankle alone).
  for (int side = 0; side < 2; ++side) store3(glob_t_[db_.roles.foot[side]], &cur_anim_feet_[side * 3]);

  lock_feet(fp, decay);

  for (int j = 0; j < J_; ++j) {
    store3(glob_t_[j], &cur_gpos_[j * 3]);
    store3(loc_t_[j], &cur_lpos_[j * 3]);
    quat_store(glob_r_[j], &cur_grot_[j * 4]);
    quat_store(loc_r_[j], &cur_lrot_[j * 4]);
  }
}

// Foot locking and IK on a frame's pose (glob_t_ holds the animated pose; decay false: a reset).
void Character::lock_feet(const FramePose& fp, bool decay) {
  const bool locking = options_.ik && options_.foot_locking;
  for (int side = 0; side < 2; ++side) {
    const bool contact = fp.contacts[side] != 0;
    const Vec3 animated = glob_t_[db_.roles.foot[side]];
    if (!locking || !decay) {
      locked_[side] = released_in_contact_[side] = false;
      lock_weight_[side] = cur_lock_w_[side] = 0;
      if (!locking) continue;
    }
    // A lock released during a contact may lock again once it has blended out: the foot then
    // stays where it is shown for the rest of the contact instead of following the animation.
    if (!contact || lock_weight_[side] <= 0.0f) released_in_contact_[side] = false;
    if (locked_[side] && (!contact || (animated - lock_position_[side]).norm() > options_.lock_release_distance)) {
      locked_[side] = false;
      released_in_contact_[side] = contact;
    }
    if (contact && !locked_[side] && !released_in_contact_[side]) {
      // Lock at once where the foot would be shown now (the animated ankle, or the ankle
      // still blending out of an earlier lock): no jump, and from this frame on the foot
      // does not move. Only the release is blended, since that is where the locked and
      // animated ankles differ. A reset (no decay) locks too, at the new pose: a foot planted
      // in the first frame stays planted in the second.
      const float w_prev = smoothstep(lock_weight_[side]);
      lock_position_[side] = animated + w_prev * (lock_position_[side] - animated);
      locked_[side] = true;
      lock_weight_[side] = 1.0f;
    }
    const float rate = options_.lock_blend_time > 0 ? dt_ / options_.lock_blend_time : 1.0f;
    lock_weight_[side] = std::clamp(lock_weight_[side] + (locked_[side] ? rate : -rate), 0.0f, 1.0f);
    const float w = smoothstep(lock_weight_[side]);
    cur_lock_w_[side] = w;
    if (w > 0) {
      // The lock holds the ankle's ground position; its height follows the animation (the
      // heel rises before toe-off while the hips move on: holding the height too would ask
      // for a longer leg than the character has, and a straight leg drags the ankle along).
      Vec3 target = animated + w * (lock_position_[side] - animated);
      target.y() = animated.y();
      solve_leg(side, target);
    }
  }
}

void Character::play(const PlayedFrames& frames, bool transition, float cost, const float* anchor) {
  last_cost_ = cost;
  last_transition_ = transition;
  last_match_ = frames.frame(0);
  const bool blend = options_.poses && inertializer_.enabled();
  const bool anchored = transition && anchor != nullptr;  // (0, 0): root_shift and the blend change nothing
  if (anchored) root_shift(root_, anchor);
  if (blend && transition) {
    blend_velocity(vel_a_, vel_b_, src_vel_);  // the velocity of the frame shown now
    frames.pose(0, fp_a_);
    frames.pose(1, fp_b_);
    blend_velocity(fp_a_, fp_b_, dst_vel_);
    blend_pose_of(fp_shown_, src_);
    if (anchored) {  // the pose shown now, seen from the moved root
      src_.hips_position.x() -= anchor[0];
      src_.hips_position.z() -= anchor[1];
    }
    blend_pose_of(fp_a_, dst_);
    inertializer_.transition(src_, src_vel_, dst_, dst_vel_);
  }
  const int F = options_.frames_per_step;
  uint8_t contacts[2];
  for (int k = 0; k < F; ++k) {
    root_advance(root_, frames.root_delta(k));
    if (options_.poses) {
      std::swap(fp_before_, fp_shown_);  // O(1): the pose shown before this frame
      frames.pose(k + 1, fp_shown_);
      show_frame(fp_shown_, true);
    }
    frames.contacts(k + 1, contacts);
    record_step_frame(k, frames.frame(k + 1), contacts);
  }
  frame_ = frames.frame(F);
  if (blend) frames.velocity_pair(F, fp_before_, vel_a_, vel_b_);
}

void Character::record_step_frame(int k, int64_t f, const uint8_t* contacts) {
  const size_t JJ = static_cast<size_t>(J_);
  played_[k] = f;
  roots_[k * 3] = root_.x;
  roots_[k * 3 + 1] = root_.z;
  roots_[k * 3 + 2] = root_.yaw;
  contacts_[k * 2] = contacts[0];
  contacts_[k * 2 + 1] = contacts[1];
  if (!options_.poses) return;
  lock_w_out_[k * 2] = cur_lock_w_[0];
  lock_w_out_[k * 2 + 1] = cur_lock_w_[1];
  std::copy(cur_gpos_.begin(), cur_gpos_.end(), gpos_.begin() + k * JJ * 3);
  std::copy(cur_lpos_.begin(), cur_lpos_.end(), lpos_.begin() + k * JJ * 3);
  std::copy(cur_grot_.begin(), cur_grot_.end(), grot_.begin() + k * JJ * 4);
  std::copy(cur_lrot_.begin(), cur_lrot_.end(), lrot_.begin() + k * JJ * 4);
  std::copy(cur_anim_feet_, cur_anim_feet_ + 6, anim_feet_.begin() + k * 6);
}

}  // namespace mmrl
