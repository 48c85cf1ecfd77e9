#include "mmrl/compressed.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "mmrl/kdtree.hpp"
#include "mmrl/search.hpp"

namespace mmrl {

namespace {

inline float elu(float x) { return x > 0.0f ? x : std::expm1(x); }

void check_size(const std::vector<float>& v, size_t n, const std::string& what) {
  if (v.size() != n)
    throw std::invalid_argument(what + ": expected " + std::to_string(n) + " floats, got " + std::to_string(v.size()));
}

}  // namespace

int Mlp::max_width() const {
  int w = 0;
  for (const Layer& l : layers) w = std::max({w, l.in, l.out});
  return w;
}

size_t Mlp::num_parameters() const {
  size_t n = 0;
  for (const Layer& l : layers) n += l.weight.size() + l.bias.size();
  return n;
}

void Mlp::check(const std::string& what) const {
  if (layers.empty()) throw std::invalid_argument(what + ": no layers");
  for (size_t k = 0; k < layers.size(); ++k) {
    const Layer& l = layers[k];
    const std::string name = what + " layer " + std::to_string(k);
    if (l.in < 1 || l.out < 1) throw std::invalid_argument(name + ": sizes must be >= 1");
    if (k > 0 && l.in != layers[k - 1].out)
      throw std::invalid_argument(name + ": takes " + std::to_string(l.in) + " inputs, the layer before gives " +
                                  std::to_string(layers[k - 1].out));
    check_size(l.weight, static_cast<size_t>(l.in) * l.out, name + " weight");
    check_size(l.bias, static_cast<size_t>(l.out), name + " bias");
    for (float v : l.weight)
      if (!std::isfinite(v)) throw std::invalid_argument(name + ": weight is not finite");
    for (float v : l.bias)
      if (!std::isfinite(v)) throw std::invalid_argument(name + ": bias is not finite");
  }
}

void Mlp::pack() {
  for (Layer& l : layers) {
    const int blocks = (l.out + kLanes - 1) / kLanes;
    l.packed.assign(static_cast<size_t>(blocks) * l.in * kLanes, 0.0f);
    for (int o = 0; o < l.out; ++o)
      for (int i = 0; i < l.in; ++i)
        l.packed[(static_cast<size_t>(o / kLanes) * l.in + i) * kLanes + o % kLanes] =
            l.weight[static_cast<size_t>(o) * l.in + i];
  }
}

namespace {

// y = W x + b over packed weights: four blocks of 8 outputs at a time (four independent sums,
// so the adds pipeline), each output's inputs summed in order.
MMRL_MULTIVERSION void dense_forward(const float* packed, const float* bias, const float* x, float* y, int in,
                                     int out) {
  const int blocks = (out + kLanes - 1) / kLanes;
  const size_t stride = static_cast<size_t>(in) * kLanes;
  auto store = [&](int b, const Lanes& acc) {
    float tmp[kLanes];
    std::memcpy(tmp, &acc, sizeof(tmp));
    for (int l = 0; l < kLanes && b * kLanes + l < out; ++l) y[b * kLanes + l] = tmp[l] + bias[b * kLanes + l];
  };
  int b = 0;
  for (; b + 4 <= blocks; b += 4) {
    const float* w = packed + b * stride;
    Lanes a0 = {}, a1 = {}, a2 = {}, a3 = {};
    for (int i = 0; i < in; ++i) {
      const float xi = x[i];
      const float* wi = w + i * kLanes;
      a0 += xi * load_lanes(wi);
      a1 += xi * load_lanes(wi + stride);
      a2 += xi * load_lanes(wi + 2 * stride);
      a3 += xi * load_lanes(wi + 3 * stride);
    }
    store(b, a0);
    store(b + 1, a1);
    store(b + 2, a2);
    store(b + 3, a3);
  }
  for (; b < blocks; ++b) {
    const float* w = packed + b * stride;
    Lanes a = {};
    for (int i = 0; i < in; ++i) a += x[i] * load_lanes(w + i * kLanes);
    store(b, a);
  }
}

}  // namespace

void Mlp::forward(const float* in, float* out, float* scratch) const {
  const int w = max_width();
  float* buf[2] = {scratch, scratch + w};
  const float* x = in;
  for (size_t k = 0; k < layers.size(); ++k) {
    const Layer& l = layers[k];
    const bool last = k + 1 == layers.size();
    float* y = last ? out : buf[k % 2];
    dense_forward(l.packed.data(), l.bias.data(), x, y, l.in, l.out);
    if (!last)
      for (int i = 0; i < l.out; ++i) y[i] = elu(y[i]);
    x = y;
  }
}

void CompressedModel::check() const {
  if (num_joints < 1 || latent < 1) throw std::invalid_argument("compressed model: joints and latent must be >= 1");
  decompressor.check("decompressor");
  stepper.check("stepper");
  projector.check("projector");
  const int S = state_dim(), P = pose_dim();
  auto dims = [](const Mlp& m, int in, int out, const char* name) {
    if (m.input_dim() != in || m.output_dim() != out)
      throw std::invalid_argument(std::string(name) + ": maps " + std::to_string(m.input_dim()) + " -> " +
                                  std::to_string(m.output_dim()) + ", the model needs " + std::to_string(in) + " -> " +
                                  std::to_string(out));
  };
  dims(decompressor, S, P, "decompressor");
  dims(stepper, S, S, "stepper");
  dims(projector, kFeatureDim, S, "projector");
  check_size(y_mean, P, "pose mean");
  check_size(y_std, P, "pose scale");
  check_size(z_mean, latent, "latent mean");
  check_size(z_std, latent, "latent scale");
  if (!fixed_joints.empty() || !fixed_translations.empty()) {
    if (fixed_joints.size() != static_cast<size_t>(num_joints))
      throw std::invalid_argument("fixed joints: expected " + std::to_string(num_joints) + " flags");
    check_size(fixed_translations, static_cast<size_t>(num_joints) * 3, "fixed translations");
    for (float v : fixed_translations)
      if (!std::isfinite(v)) throw std::invalid_argument("fixed translations: not finite");
  }
}

void CompressedModel::prepare() {
  check();
  decompressor.pack();
  stepper.pack();
  projector.pack();
}

bool CompressedModel::prepared() const {
  for (const Mlp* m : {&decompressor, &stepper, &projector})
    for (const Mlp::Layer& l : m->layers)
      if (l.packed.size() != static_cast<size_t>((l.out + kLanes - 1) / kLanes) * l.in * kLanes) return false;
  return true;
}

CompressedScratch CompressedModel::make_scratch() const {
  const int w = std::max({decompressor.max_width(), stepper.max_width(), projector.max_width()});
  CompressedScratch s;
  s.a.assign(static_cast<size_t>(2 * w), 0.0f);
  s.b.assign(static_cast<size_t>(std::max(state_dim(), pose_dim())), 0.0f);
  s.state.assign(static_cast<size_t>(state_dim()), 0.0f);
  s.pose_input.assign(static_cast<size_t>(state_dim()), 0.0f);
  return s;
}

size_t CompressedModel::num_parameters() const {
  return decompressor.num_parameters() + stepper.num_parameters() + projector.num_parameters();
}

size_t CompressedModel::memory_bytes() const {
  return sizeof(float) * (num_parameters() + y_mean.size() + y_std.size() + z_mean.size() + z_std.size() +
                          fixed_translations.size()) + fixed_joints.size();
}

void CompressedModel::decode(const float* state, float* pose, CompressedScratch& scratch) const {
  float* in = scratch.pose_input.data();
  for (int k = 0; k < kFeatureDim; ++k) in[k] = state[k];
  for (int k = 0; k < latent; ++k) in[kFeatureDim + k] = state[kFeatureDim + k] * z_std[k] + z_mean[k];
  decompressor.forward(in, pose, scratch.a.data());
  const int P = pose_dim();
  for (int k = 0; k < P; ++k) pose[k] = pose[k] * y_std[k] + y_mean[k];
  for (size_t j = 0; j < fixed_joints.size(); ++j)
    if (fixed_joints[j])
      for (int c = 0; c < 3; ++c) pose[6 * num_joints + 3 * j + c] = fixed_translations[3 * j + c];
}

void CompressedModel::step(float* state, CompressedScratch& scratch) const {
  float* delta = scratch.b.data();
  stepper.forward(state, delta, scratch.a.data());
  const int S = state_dim();
  for (int k = 0; k < S; ++k) state[k] += delta[k];
}

void CompressedModel::project(const float* query, float* state, CompressedScratch& scratch) const {
  projector.forward(query, state, scratch.a.data());
}

bool compressed_decision(const CompressedModel& model, const float* current, const float* query,
                         float transition_cost, float* projected, float* cost, CompressedScratch& scratch) {
  const float stay = feature_distance(query, current);
  model.project(query, projected, scratch);
  const float jump = feature_distance(query, projected);
  const bool transition = jump + transition_cost < stay;
  if (cost) *cost = transition ? jump : stay;
  return transition;
}

void compressed_playback(const CompressedModel& model, const float* start, int frames, float* rows, float* end,
                         CompressedScratch& scratch) {
  float* s = scratch.state.data();
  const int S = model.state_dim(), P = model.pose_dim();
  std::copy(start, start + S, s);
  model.decode(s, rows, scratch);
  for (int k = 1; k <= frames; ++k) {
    model.step(s, scratch);
    model.decode(s, rows + static_cast<size_t>(k) * P, scratch);
  }
  std::copy(s, s + S, end);
}

Quat rotation_from_6d(const float* six) {
  // Row-major first two columns: six = [m00, m01, m10, m11, m20, m21].
  Vec3 c1(six[0], six[2], six[4]), c2(six[1], six[3], six[5]);
  const float n1 = c1.norm();
  c1 = n1 > 1e-12f ? Vec3(c1 / n1) : Vec3::UnitX();
  c2 = c2 - c1.dot(c2) * c1;
  const float n2 = c2.norm();
  c2 = n2 > 1e-12f ? Vec3(c2 / n2) : Vec3(c1.unitOrthogonal());
  Mat3 m;
  m.col(0) = c1;
  m.col(1) = c2;
  m.col(2) = c1.cross(c2);
  return Quat(m).normalized();
}

}  // namespace mmrl
