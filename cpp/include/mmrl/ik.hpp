// Analytic two-bone IK (hip -> knee -> ankle) as a small job: fill the inputs, Validate(),
// Run(), read the outputs.
//
// Inputs are global (world or character space, meters; any one space for all of them):
//   hip, knee, ankle   current joint positions (bone lengths are taken from them);
//   target             where the ankle should go;
//   pole               a point the knee should bend toward; by default (pole_from_knee) the
//                      current knee, so the leg keeps its bending plane;
//   margin             the leg is never stretched closer than this to straight (meters;
//                      a locked straight knee pops). The reach is |hip-knee| + |knee-ankle| - margin.
// Outputs: global rotation corrections, to be applied on the left of the current global
// rotations of the hip (upper leg) and knee (lower leg) joints:
//   new_global_upper = hip_correction * old_global_upper
//   new_global_lower = knee_correction * old_global_lower
// and the new knee and ankle positions. The ankle lands on the target when it is within
// reach, otherwise on the line from the hip toward the target at the full reach.
#pragma once

#include "mmrl/math.hpp"

namespace mmrl {

struct IkTwoBoneJob {
  // Inputs.
  Vec3 hip = Vec3::Zero(), knee = Vec3::Zero(), ankle = Vec3::Zero();
  Vec3 target = Vec3::Zero();
  Vec3 pole = Vec3::Zero();
  bool pole_from_knee = true;
  float margin = 0.015f;  // meters
  // Used when the leg is straight and the pole gives no bending plane: a direction the knee
  // should point to (for legs, the character's forward).
  Vec3 fallback_bend_direction = Vec3::UnitZ();

  // Outputs.
  Quat hip_correction = Quat::Identity();
  Quat knee_correction = Quat::Identity();
  Vec3 new_knee = Vec3::Zero(), new_ankle = Vec3::Zero();
  bool reached = false;

  // True when every input is finite, both bones are longer than 1 mm and the margin is in
  // [0, shorter bone).
  bool Validate() const;
  // Returns false (and leaves the outputs as identity / unchanged positions) if invalid.
  bool Run();
};

}  // namespace mmrl
