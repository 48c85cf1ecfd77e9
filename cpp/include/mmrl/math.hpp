// Eigen aliases, quaternions and the character (heading) frame.
//
// World space: meters, Y up, right-handed. The character frame of a frame has its origin on
// the ground under the hips, Y up, Z along the character's forward direction and X to the
// character's left (X = Y x Z). A heading is a yaw angle about +Y in radians, measured so
// that forward = (sin(yaw), 0, cos(yaw)); a positive change of yaw is a left
// (counter-clockwise seen from above) turn.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace mmrl {

using Vec2 = Eigen::Vector2f;
using Vec3 = Eigen::Vector3f;
using Quat = Eigen::Quaternionf;
using Mat3 = Eigen::Matrix3f;

constexpr float kPi = 3.14159265358979323846f;

inline float deg_to_rad(float d) { return d * (kPi / 180.0f); }

// Wraps an angle to (-pi, pi].
inline float wrap_angle(float a) {
  a = std::fmod(a + kPi, 2.0f * kPi);
  if (a < 0) a += 2.0f * kPi;
  return a - kPi;
}

// Yaw of a horizontal direction (x, z): atan2(x, z).
inline float yaw_from_forward(float x, float z) { return std::atan2(x, z); }

inline Vec3 forward_from_yaw(float yaw) { return Vec3(std::sin(yaw), 0.0f, std::cos(yaw)); }

inline Quat quat_from_yaw(float yaw) { return Quat(Eigen::AngleAxisf(yaw, Vec3::UnitY())); }

// World -> character frame for a horizontal offset: rotates by -yaw about Y.
// Returns the (x, z) components in the character frame.
inline Vec2 world_to_local_xz(float dx, float dz, float yaw) {
  const float c = std::cos(yaw), s = std::sin(yaw);
  // Character axes in world: X_c = (c, 0, -s), Z_c = (s, 0, c).
  return Vec2(c * dx - s * dz, s * dx + c * dz);
}

// Character frame -> world for a horizontal offset.
inline Vec2 local_to_world_xz(float lx, float lz, float yaw) {
  const float c = std::cos(yaw), s = std::sin(yaw);
  return Vec2(c * lx + s * lz, -s * lx + c * lz);
}

// World -> character frame for a 3-d vector (rotation only).
inline Vec3 world_to_local_dir(const Vec3& v, float yaw) {
  const Vec2 h = world_to_local_xz(v.x(), v.z(), yaw);
  return Vec3(h.x(), v.y(), h.y());
}

// Reflection across the world YZ plane (x -> -x) applied to a rotation: R -> M R M.
inline Quat quat_mirror_x(const Quat& q) { return Quat(q.w(), q.x(), -q.y(), -q.z()); }

}  // namespace mmrl
