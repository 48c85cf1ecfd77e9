#include "mmrl/stitch.hpp"

#include <algorithm>

namespace mmrl {

void Inertializer::reset(int num_joints, int hips, const std::vector<bool>& blended, float halflife) {
  hips_ = hips;
  halflife_ = halflife;
  blended_ = blended;
  blended_.resize(num_joints, true);
  rot_.assign(num_joints, Vec3::Zero());
  rot_vel_.assign(num_joints, Vec3::Zero());
  clear();
}

void Inertializer::clear() {
  std::fill(rot_.begin(), rot_.end(), Vec3::Zero());
  std::fill(rot_vel_.begin(), rot_vel_.end(), Vec3::Zero());
  hips_pos_ = hips_pos_vel_ = hips_rot_ = hips_rot_vel_ = Vec3::Zero();
}

void Inertializer::transition(const BlendPose& src, const BlendVelocity& src_vel, const BlendPose& dst,
                              const BlendVelocity& dst_vel) {
  if (!enabled()) return;
  const int J = static_cast<int>(rot_.size());
  for (int j = 0; j < J; ++j) {
    if (!blended_[j] || j == hips_) continue;
    // Shown source = exp(offset) * src; the new offset maps dst onto it.
    const Quat shown = quat_from_rotation_vector(rot_[j]) * src.rotations[j];
    rot_[j] = quat_to_rotation_vector(shown * dst.rotations[j].conjugate());
    rot_vel_[j] = rot_vel_[j] + src_vel.angular[j] - dst_vel.angular[j];
  }
  const Quat shown = quat_from_rotation_vector(hips_rot_) * src.hips_rotation;
  hips_rot_ = quat_to_rotation_vector(shown * dst.hips_rotation.conjugate());
  hips_rot_vel_ = hips_rot_vel_ + src_vel.hips_angular - dst_vel.hips_angular;
  hips_pos_ = hips_pos_ + src.hips_position - dst.hips_position;
  hips_pos_vel_ = hips_pos_vel_ + src_vel.hips_linear - dst_vel.hips_linear;
}

void Inertializer::update(float dt, const BlendPose& in, BlendPose& out) {
  const int J = static_cast<int>(rot_.size());
  if (!enabled()) {
    if (&out != &in) out = in;
    return;
  }
  for (int j = 0; j < J; ++j) {
    if (!blended_[j] || j == hips_) {
      out.rotations[j] = in.rotations[j];
      continue;
    }
    spring_decay(rot_[j], rot_vel_[j], halflife_, dt);
    out.rotations[j] = (quat_from_rotation_vector(rot_[j]) * in.rotations[j]).normalized();
  }
  spring_decay(hips_rot_, hips_rot_vel_, halflife_, dt);
  spring_decay(hips_pos_, hips_pos_vel_, halflife_, dt);
  out.hips_rotation = (quat_from_rotation_vector(hips_rot_) * in.hips_rotation).normalized();
  out.hips_position = in.hips_position + hips_pos_;
}

float Inertializer::max_rotation_offset() const {
  float m = hips_rot_.norm();
  for (size_t j = 0; j < rot_.size(); ++j)
    if (blended_[j]) m = std::max(m, rot_[j].norm());
  return m;
}

}  // namespace mmrl
