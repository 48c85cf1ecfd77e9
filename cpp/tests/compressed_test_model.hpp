// A compressed controller with random weights for the test database's skeleton
// (env_test_database.hpp): what the compressed tests and the rule tests play.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "env_test_database.hpp"
#include "mmrl/compressed.hpp"

namespace mmrl {
namespace testing_db {

inline Mlp random_mlp(std::mt19937& rng, const std::vector<int>& sizes, float scale) {
  std::normal_distribution<float> n(0.0f, 1.0f);
  Mlp m;
  for (size_t k = 0; k + 1 < sizes.size(); ++k) {
    Mlp::Layer l;
    l.in = sizes[k];
    l.out = sizes[k + 1];
    for (int i = 0; i < l.in * l.out; ++i) l.weight.push_back(scale * n(rng) / std::sqrt(float(l.in)));
    for (int i = 0; i < l.out; ++i) l.bias.push_back(0.1f * n(rng));
    m.layers.push_back(std::move(l));
  }
  return m;
}

// A model of the test database's skeleton with random weights (a small stepper, so states stay bounded).
inline CompressedModel random_model(uint32_t seed) {
  std::mt19937 rng(seed);
  CompressedModel m;
  m.num_joints = database().num_joints;
  m.latent = 4;
  const int S = m.state_dim(), P = m.pose_dim();
  m.decompressor = random_mlp(rng, {S, 16, P}, 1.0f);
  m.stepper = random_mlp(rng, {S, 16, S}, 0.02f);
  m.projector = random_mlp(rng, {kFeatureDim, 16, S}, 1.0f);
  m.y_mean.assign(P, 0.0f);
  m.y_std.assign(P, 0.1f);
  // Rotations near the identity (6D: columns (1,0,0), (0,1,0) row-major), contacts near 0.5.
  for (int j = 0; j < m.num_joints; ++j) {
    m.y_mean[6 * j + 0] = 1.0f;
    m.y_mean[6 * j + 3] = 1.0f;
  }
  m.y_mean[9 * m.num_joints + 3] = m.y_mean[9 * m.num_joints + 4] = 0.5f;
  m.y_mean[9 * m.num_joints] = 0.0f;
  m.y_mean[9 * m.num_joints + 1] = 0.03f;  // walking forward
  m.z_mean.assign(m.latent, 0.0f);
  m.z_std.assign(m.latent, 1.0f);
  m.prepare();
  return m;
}

}  // namespace testing_db
}  // namespace mmrl
