// Import steps between the BVH text and a database (bvh_parse applies them in this order):
// bring the world to Y up, then (after the scale) resample to the database's frame rate.
// Plus a check that the result looks like a person moving over a floor, for warnings.
//
// Why: features, trajectory offsets (+10/+20/+30 frames) and the decision interval
// (6 frames) are counted in frames of a Y-up world. A Z-up file read as Y up puts the
// character on its back and its running into the vertical; a 60 fps file halves every
// offset in seconds. Both used to build without a word.
#pragma once

#include "mmrl/bvh.hpp"

namespace mmrl {

// The file's up axis, read from the skeleton: the mean direction from the feet (the mean
// of the two foot joints) to the hips over up to 16 evenly spaced frames. Z when its
// largest component is +Z, else Y. Y as well when the hips and feet cannot be found by
// name (skeleton.hpp), since Y up is the BVH convention; the plausibility check below then
// catches a wrong guess.
UpAxis motion_detect_up_axis(const Motion& motion);

// Rotates a Z-up world to Y up: -90 degrees about X, (x, y, z) -> (x, z, -y). Applied to
// the roots' translations, rotations and OFFSETs, which moves every joint; children keep
// their local transforms. The character's forward stays horizontal.
void motion_rotate_z_up_to_y_up(Motion& motion);

// The file's frame rate, snapped to the nearest integer when within 1e-4 relative of it:
// BVH files round Frame Time (0.0333333 s), and snapping keeps 60 -> 30 fps an exact 2:1.
float motion_nominal_fps(const Motion& motion);

// True when the nominal rate differs from `fps` by more than 1e-4 relative.
bool motion_needs_resample(const Motion& motion, float fps);

// The motion at `fps` frames per second over the same time span: output frame k sits at
// t = k / fps seconds; frames past the last input frame's time are dropped. Local
// translations are interpolated linearly and local rotations by slerp (shortest arc);
// an output time on an input frame copies that frame exactly. The new Frame Time is 1 / fps
// to 7 significant digits, as BVH files store it. Throws std::invalid_argument for fps <= 0
// or not finite, and when the result would have more than 2^28 frames.
Motion motion_resample(const Motion& motion, float fps);

// What a person moving over a floor looks like, measured on an imported (meters, Y up)
// motion. Joint positions of the body only: End Sites and root joints are left out (a root
// is often a ground marker that stays at the origin while the body walks away).
struct MotionPlausibility {
  float seconds = 0;             // duration, (frames - 1) / fps
  float height = 0;              // m, median over up to 16 frames of the joints' vertical extent
  float horizontal_extent = 0;   // m, median over the same frames of the largest horizontal joint distance
  float vertical_travel = 0;     // m, max - min height of the body's centroid over the clip
  float horizontal_path = 0;     // m, path length of the centroid's ground projection
  float median_horizontal_speed = 0;  // m/s, of the centroid's ground projection
};

MotionPlausibility motion_plausibility(const Motion& motion);

}  // namespace mmrl
