// The 27-d motion-matching feature, its blocks and normalisation.
//
// All features of frame i are in frame i's character frame (see math.hpp), meters and m/s:
//   [0:3]  left foot position        [3:6]  right foot position
//   [6:9]  left foot velocity        [9:12] right foot velocity
//   [12:15] hips velocity
//   [15:17] root position (x, z) at +10 frames, [17:19] facing direction (x, z) at +10
//   [19:21], [21:23] the same at +20 frames;    [23:25], [25:27] at +30 frames.
// Directions are unit vectors. The first 15 columns are the pose part c, the last 12 the
// trajectory part t (the policy's action).
#pragma once

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "mmrl/math.hpp"

namespace mmrl {

constexpr int kFeatureDim = 27;
constexpr int kPoseDim = 15;
constexpr int kTrajectoryDim = 12;
constexpr int kTrajectoryOffsets[3] = {10, 20, 30};
// Columns of horizon k's root position (x, z) and facing direction (x, z) in a feature row.
constexpr int trajectory_position_column(int k) { return kPoseDim + 4 * k; }
constexpr int trajectory_direction_column(int k) { return kPoseDim + 4 * k + 2; }
constexpr int kNumBlocks = 5;
// A frame stands (is idle) when its +30-frame trajectory sample is nearer than this (m): the
// measure of mmrl.motion.kinds (IDLE_METERS), mmrl db info and the raw idle frames' floor.
constexpr double kIdleMeters = 0.15;
// A frame stands still when it also turns less than this over that second (degrees): an idle
// frame may turn in place, a frame that stands still does not (docs/arrive.md).
constexpr double kStillDegrees = 20.0;
// Whether a feature row (raw, kFeatureDim floats) is idle: kIdleMeters over the next second.
inline bool feature_row_idle(const float* f) {
  const int p = trajectory_position_column(2);
  return std::hypot(f[p], f[p + 1]) < static_cast<float>(kIdleMeters);
}
// A foot slower than this (m/s, by its feature velocity) is planted: the arrive task's still
// idles last while both feet are, and its stand's transitions keep both planted feet in place.
constexpr float kPlantedFootSpeed = 0.3f;
// Whether a foot with velocity v (3 floats, m/s: a raw feature row's [6, 9) left, [9, 12) right)
// is planted.
inline bool foot_planted(const float* v) {
  return v[0] * v[0] + v[1] * v[1] + v[2] * v[2] < kPlantedFootSpeed * kPlantedFootSpeed;
}
// Whether an idle feature row also stands still: it turns less than kStillDegrees.
inline bool idle_row_stands_still(const float* f) {
  const int d = trajectory_direction_column(2);
  return std::abs(std::atan2(f[d], f[d + 1])) < static_cast<float>(kStillDegrees) * (kPi / 180.0f);
}

// A block shares one normalisation scale and one weight. Columns need not be contiguous
// (trajectory positions and directions interleave by horizon).
struct FeatureBlock {
  const char* name;
  std::array<int, 6> columns;
  int size;
  float default_weight;  // Holden's defaults
};

const std::array<FeatureBlock, kNumBlocks>& feature_blocks();

// Character frame smoothing: the raw forward (left upper leg - right upper leg) x up is
// filtered with a Gaussian of this standard deviation (seconds) within each clip, which
// removes the pelvis sway of the gait (about 1 Hz) while keeping turns.
constexpr float kForwardSmoothingSigmaSeconds = 0.3f;

// Computes the character frame of every frame of one clip. hips, left/right upper leg are
// global positions (F x 3, meters). Outputs root positions (F x 3, y = 0) and yaws (F).
void clip_character_frames(int num_frames, float fps, const float* hips, const float* left_upper_leg,
                           const float* right_upper_leg, float* root_positions, float* root_yaws);

// Features of every frame of one clip (F x 27) from global joint positions of the feet and
// hips (F x 3 each) and the clip's character frames. Velocities are central differences
// (one-sided at the clip ends); trajectory samples past the clip end clamp to its last
// frame (such frames are not valid matches).
void clip_features(int num_frames, float fps, const float* left_foot, const float* right_foot, const float* hips,
                   const float* root_positions, const float* root_yaws, float* features);

// Normalisation: mean per column; one scale per block (the mean of its columns' standard
// deviations); normalized = (f - mean) / scale * weight. Computed over all frames.
struct FeatureNormalization {
  std::array<float, kFeatureDim> mean{};
  std::array<float, kNumBlocks> block_scale{};
  std::array<float, kNumBlocks> weights{};
  // Per-column divisor: block_scale / weight (normalized = (f - mean) / column_scale).
  std::array<float, kFeatureDim> column_scale() const;
};

FeatureNormalization features_fit_normalization(const float* features, int num_frames,
                                                const std::array<float, kNumBlocks>& weights);

void features_normalize(const FeatureNormalization& norm, const float* features, int num_rows, float* out);

}  // namespace mmrl
