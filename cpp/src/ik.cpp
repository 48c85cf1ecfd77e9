#include "mmrl/ik.hpp"

#include <algorithm>
#include <cmath>

namespace mmrl {

namespace {

bool finite(const Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

// Unit part of v orthogonal to unit u; zero if v is (nearly) parallel to u.
Vec3 orthogonal_part(const Vec3& v, const Vec3& u) {
  const Vec3 p = v - u * u.dot(v);
  const float n = p.norm();
  return n > 1e-6f ? Vec3(p / n) : Vec3(Vec3::Zero());
}

}  // namespace

bool IkTwoBoneJob::Validate() const {
  if (!finite(hip) || !finite(knee) || !finite(ankle) || !finite(target) || !finite(fallback_bend_direction))
    return false;
  if (!pole_from_knee && !finite(pole)) return false;
  const float upper = (knee - hip).norm(), lower = (ankle - knee).norm();
  if (!(upper > 1e-3f) || !(lower > 1e-3f)) return false;
  if (!std::isfinite(margin) || margin < 0 || margin >= std::min(upper, lower)) return false;
  return true;
}

bool IkTwoBoneJob::Run() {
  hip_correction = knee_correction = Quat::Identity();
  new_knee = knee;
  new_ankle = ankle;
  reached = false;
  if (!Validate()) return false;
  const float upper = (knee - hip).norm(), lower = (ankle - knee).norm();
  const float reach = upper + lower - margin;
  // The shortest hip-ankle distance the bones allow (knee folded), plus the same margin.
  const float shortest = std::fabs(upper - lower) + margin;

  Vec3 to_target = target - hip;
  float dist = to_target.norm();
  Vec3 dir;
  if (dist > 1e-6f) {
    dir = to_target / dist;
  } else {
    dir = (ankle - hip).normalized();
  }
  reached = dist <= reach && dist >= shortest;
  dist = std::min(reach, std::max(shortest, dist));

  // Bending plane: the pole (current knee by default) minus its part along the leg.
  const Vec3 pole_point = pole_from_knee ? knee : pole;
  Vec3 bend = orthogonal_part(pole_point - hip, dir);
  if (bend.isZero()) bend = orthogonal_part(fallback_bend_direction, dir);
  if (bend.isZero()) bend = orthogonal_part(Vec3::UnitX(), dir);
  if (bend.isZero()) bend = orthogonal_part(Vec3::UnitZ(), dir);

  // Law of cosines: the angle at the hip between the hip-ankle line and the thigh.
  const float cos_hip = std::max(-1.0f, std::min(1.0f, (upper * upper + dist * dist - lower * lower) / (2 * upper * dist)));
  const float sin_hip = std::sqrt(std::max(0.0f, 1.0f - cos_hip * cos_hip));
  new_knee = hip + upper * (cos_hip * dir + sin_hip * bend);
  new_ankle = hip + dist * dir;

  // Swing the thigh onto the new knee, then the shin (as carried by the thigh) onto the new ankle.
  hip_correction = Quat::FromTwoVectors(knee - hip, new_knee - hip).normalized();
  const Vec3 carried_shin = hip_correction * (ankle - knee);
  knee_correction = (Quat::FromTwoVectors(carried_shin, new_ankle - new_knee) * hip_correction).normalized();
  return true;
}

}  // namespace mmrl
