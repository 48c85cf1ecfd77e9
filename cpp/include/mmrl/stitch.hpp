// Inertialization: transitions between database frames without pose jumps.
//
// At a transition the pose that would have played next (the source: the current frame's
// continuation, including any offset still decaying) and the pose of the new match (the
// destination) differ. The difference is stored as an offset, with the difference of their
// velocities, and added to every following frame while a critically damped spring pulls it
// to zero. The shown pose therefore starts exactly where the old one was, moving as it was
// moving, and converges to the new animation.
//
// What is offset (all in the character frame of the frame being played, see math.hpp):
//   - every joint's local rotation, except the hips and their ancestors (a rotation vector,
//     radians, applied on the left: shown = exp(offset) * animated);
//   - the hips' rotation and position relative to the character frame (the "root-relative"
//     hips transform; meters).
// The ancestors of the hips (for example a static BVH root dummy) are structural: they get
// no offset; the hips are re-expressed below them after blending.
//
// Spring: with y = 2 ln 2 / halflife, an offset x0 with velocity v0 evolves as
//   x(t) = (x0 + (v0 + y x0) t) e^{-y t}; it is below 1% of x0 (v0 = 0) after 5 half-lives.
// halflife <= 0 turns inertialization off (a hard switch).
#pragma once

#include <vector>

#include "mmrl/math.hpp"

namespace mmrl {

// Critically damped decay of an offset toward zero over dt seconds (in place).
inline void spring_decay(Vec3& x, Vec3& v, float halflife, float dt) {
  const float y = 2.0f * 0.69314718056f / halflife;
  const Vec3 j1 = v + x * y;
  const float e = std::exp(-y * dt);
  x = (x + j1 * dt) * e;
  v = (v - j1 * (y * dt)) * e;
}

// Rotation vector (axis * angle, radians) of a unit quaternion, shortest path.
inline Vec3 quat_to_rotation_vector(Quat q) {
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Vec3 v = q.vec();
  const float s = v.norm();
  if (s < 1e-8f) return 2.0f * v;
  return v * (2.0f * std::atan2(s, q.w()) / s);
}

inline Quat quat_from_rotation_vector(const Vec3& r) {
  const float a = r.norm();
  if (a < 1e-8f) return Quat(1.0f, 0.5f * r.x(), 0.5f * r.y(), 0.5f * r.z()).normalized();
  return Quat(Eigen::AngleAxisf(a, r / a));
}

// A pose prepared for blending: local rotations of every joint plus the hips' transform in
// the character frame (meters). Sized once; no allocation afterwards.
struct BlendPose {
  std::vector<Quat> rotations;  // J, local (the hips' entry is unused: see hips_rotation)
  Vec3 hips_position = Vec3::Zero();
  Quat hips_rotation = Quat::Identity();
  void resize(int num_joints) { rotations.assign(num_joints, Quat::Identity()); }
};

// Velocities of a BlendPose (rad/s as rotation vectors in parent space; m/s).
struct BlendVelocity {
  std::vector<Vec3> angular;  // J
  Vec3 hips_linear = Vec3::Zero();
  Vec3 hips_angular = Vec3::Zero();
  void resize(int num_joints) { angular.assign(num_joints, Vec3::Zero()); }
};

class Inertializer {
 public:
  // blended[j] = false for joints that get no offset (the hips' ancestors); the hips use
  // the hips_* members. halflife in seconds (<= 0: hard switch).
  void reset(int num_joints, int hips, const std::vector<bool>& blended, float halflife);

  float halflife() const { return halflife_; }
  bool enabled() const { return halflife_ > 0; }

  // A transition from src (the pose that would have been shown, without offsets) to dst
  // (the new animation at the same instant), with their velocities. The current offsets
  // are folded in, so repeated transitions stay continuous.
  void transition(const BlendPose& src, const BlendVelocity& src_vel, const BlendPose& dst,
                  const BlendVelocity& dst_vel);

  // Decays the offsets by dt seconds, then writes pose + offsets into out (in may alias out).
  void update(float dt, const BlendPose& in, BlendPose& out);

  // Largest remaining offset: rotation (radians) and hips translation (meters).
  float max_rotation_offset() const;
  float hips_translation_offset() const { return hips_pos_.norm(); }
  void clear();

 private:
  int hips_ = 0;
  float halflife_ = 0.1f;
  std::vector<bool> blended_;
  std::vector<Vec3> rot_, rot_vel_;  // rotation vectors and their velocities, per joint
  Vec3 hips_pos_ = Vec3::Zero(), hips_pos_vel_ = Vec3::Zero();
  Vec3 hips_rot_ = Vec3::Zero(), hips_rot_vel_ = Vec3::Zero();
};

}  // namespace mmrl
