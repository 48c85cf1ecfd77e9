#include "mmrl/features.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace mmrl {

const std::array<FeatureBlock, kNumBlocks>& feature_blocks() {
  static const std::array<FeatureBlock, kNumBlocks> blocks = {{
      {"foot_position", {0, 1, 2, 3, 4, 5}, 6, 0.75f},
      {"foot_velocity", {6, 7, 8, 9, 10, 11}, 6, 1.0f},
      {"hips_velocity", {12, 13, 14, 0, 0, 0}, 3, 1.0f},
      {"trajectory_position", {15, 16, 19, 20, 23, 24}, 6, 1.0f},
      {"trajectory_direction", {17, 18, 21, 22, 25, 26}, 6, 1.5f},
  }};
  return blocks;
}

std::array<float, kFeatureDim> FeatureNormalization::column_scale() const {
  std::array<float, kFeatureDim> s{};
  const auto& blocks = feature_blocks();
  for (int b = 0; b < kNumBlocks; ++b)
    for (int k = 0; k < blocks[b].size; ++k) s[blocks[b].columns[k]] = block_scale[b] / weights[b];
  return s;
}

void clip_character_frames(int F, float fps, const float* hips, const float* lul, const float* rul, float* root_pos,
                           float* root_yaw) {
  std::vector<Vec2> raw(F);
  for (int i = 0; i < F; ++i) {
    // (l - r) x up = (-a_z, 0, a_x) for a = l - r.
    const float ax = lul[i * 3] - rul[i * 3], az = lul[i * 3 + 2] - rul[i * 3 + 2];
    Vec2 f(-az, ax);
    const float n = f.norm();
    raw[i] = n > 1e-8f ? Vec2(f / n) : Vec2(0.0f, 1.0f);
    root_pos[i * 3] = hips[i * 3];
    root_pos[i * 3 + 1] = 0.0f;
    root_pos[i * 3 + 2] = hips[i * 3 + 2];
  }
  const float sigma = kForwardSmoothingSigmaSeconds * fps;
  const int radius = std::max(1, static_cast<int>(std::ceil(3.0f * sigma)));
  std::vector<float> kernel(radius + 1);
  for (int k = 0; k <= radius; ++k) kernel[k] = std::exp(-0.5f * k * k / (sigma * sigma));
  for (int i = 0; i < F; ++i) {
    Vec2 acc = Vec2::Zero();
    for (int k = -radius; k <= radius; ++k) {
      const int j = i + k;
      if (j < 0 || j >= F) continue;  // truncated kernel at clip ends (renormalised implicitly)
      acc += kernel[std::abs(k)] * raw[j];
    }
    if (acc.norm() < 1e-8f) acc = raw[i];
    root_yaw[i] = yaw_from_forward(acc.x(), acc.y());
  }
}

void clip_features(int F, float fps, const float* lf, const float* rf, const float* hips, const float* root_pos,
                   const float* root_yaw, float* out) {
  auto velocity = [&](const float* p, int i) {
    if (F < 2) return Vec3(Vec3::Zero());
    const int a = std::max(0, i - 1), b = std::min(F - 1, i + 1);
    return Vec3((Vec3(p[b * 3], p[b * 3 + 1], p[b * 3 + 2]) - Vec3(p[a * 3], p[a * 3 + 1], p[a * 3 + 2])) * (fps / (b - a)));
  };
  for (int i = 0; i < F; ++i) {
    float* f = out + static_cast<size_t>(i) * kFeatureDim;
    const float yaw = root_yaw[i];
    const Vec3 origin(root_pos[i * 3], 0.0f, root_pos[i * 3 + 2]);
    auto put3 = [&](int col, const Vec3& v) {
      f[col] = v.x();
      f[col + 1] = v.y();
      f[col + 2] = v.z();
    };
    put3(0, world_to_local_dir(Vec3(lf[i * 3], lf[i * 3 + 1], lf[i * 3 + 2]) - origin, yaw));
    put3(3, world_to_local_dir(Vec3(rf[i * 3], rf[i * 3 + 1], rf[i * 3 + 2]) - origin, yaw));
    put3(6, world_to_local_dir(velocity(lf, i), yaw));
    put3(9, world_to_local_dir(velocity(rf, i), yaw));
    put3(12, world_to_local_dir(velocity(hips, i), yaw));
    for (int h = 0; h < 3; ++h) {
      const int j = std::min(F - 1, i + kTrajectoryOffsets[h]);
      const Vec2 p = world_to_local_xz(root_pos[j * 3] - origin.x(), root_pos[j * 3 + 2] - origin.z(), yaw);
      const float dyaw = root_yaw[j] - yaw;
      f[15 + h * 4] = p.x();
      f[16 + h * 4] = p.y();
      f[17 + h * 4] = std::sin(dyaw);
      f[18 + h * 4] = std::cos(dyaw);
    }
  }
}

FeatureNormalization features_fit_normalization(const float* features, int N, const std::array<float, kNumBlocks>& weights) {
  FeatureNormalization norm;
  norm.weights = weights;
  std::array<double, kFeatureDim> sum{}, sq{};
  for (int i = 0; i < N; ++i)
    for (int c = 0; c < kFeatureDim; ++c) sum[c] += features[static_cast<size_t>(i) * kFeatureDim + c];
  for (int c = 0; c < kFeatureDim; ++c) norm.mean[c] = N > 0 ? static_cast<float>(sum[c] / N) : 0.0f;
  for (int i = 0; i < N; ++i)
    for (int c = 0; c < kFeatureDim; ++c) {
      const double d = features[static_cast<size_t>(i) * kFeatureDim + c] - norm.mean[c];
      sq[c] += d * d;
    }
  const auto& blocks = feature_blocks();
  for (int b = 0; b < kNumBlocks; ++b) {
    double s = 0;
    for (int k = 0; k < blocks[b].size; ++k) s += N > 0 ? std::sqrt(sq[blocks[b].columns[k]] / N) : 0.0;
    s /= blocks[b].size;
    norm.block_scale[b] = s > 1e-8 ? static_cast<float>(s) : 1.0f;
  }
  return norm;
}

void features_normalize(const FeatureNormalization& norm, const float* features, int rows, float* out) {
  const auto scale = norm.column_scale();
  std::array<float, kFeatureDim> inv{};
  for (int c = 0; c < kFeatureDim; ++c) inv[c] = 1.0f / scale[c];
  for (int i = 0; i < rows; ++i)
    for (int c = 0; c < kFeatureDim; ++c) {
      const size_t o = static_cast<size_t>(i) * kFeatureDim + c;
      out[o] = (features[o] - norm.mean[c]) * inv[c];
    }
}

}  // namespace mmrl
