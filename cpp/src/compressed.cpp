#include "mmrl/compressed.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
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

// Y = X W^T + b for R rows of X (R <= kMaxRows) over packed weights: per block of 8 outputs, one
// load of each input's weights feeds every row (R independent sums, so the adds pipeline and a
// batch reads the weights once). Each output sums its inputs in order from 0, then adds its bias,
// whatever R is: a row's result does not depend on the batch it is in.
template <int R>
__attribute__((always_inline)) inline void dense_rows(const float* packed, const float* bias, const float* x,
                                                      int x_stride, float* y, int y_stride, int in, int out) {
  const int blocks = (out + kLanes - 1) / kLanes;
  for (int b = 0; b < blocks; ++b) {
    const float* w = packed + static_cast<size_t>(b) * in * kLanes;
    Lanes acc[R];
    for (int r = 0; r < R; ++r) acc[r] = Lanes{};
    for (int i = 0; i < in; ++i) {
      const Lanes wi = load_lanes(w + i * kLanes);
      for (int r = 0; r < R; ++r) acc[r] += x[r * x_stride + i] * wi;
    }
    const int n = std::min(kLanes, out - b * kLanes);
    for (int r = 0; r < R; ++r) {
      float tmp[kLanes];
      std::memcpy(tmp, &acc[r], sizeof(tmp));
      for (int l = 0; l < n; ++l) y[r * y_stride + b * kLanes + l] = tmp[l] + bias[b * kLanes + l];
    }
  }
}

MMRL_MULTIVERSION void dense_forward(const float* packed, const float* bias, const float* x, int x_stride, float* y,
                                     int y_stride, int in, int out, int rows) {
  switch (rows) {
    case 1: return dense_rows<1>(packed, bias, x, x_stride, y, y_stride, in, out);
    case 2: return dense_rows<2>(packed, bias, x, x_stride, y, y_stride, in, out);
    case 3: return dense_rows<3>(packed, bias, x, x_stride, y, y_stride, in, out);
    case 4: return dense_rows<4>(packed, bias, x, x_stride, y, y_stride, in, out);
    case 5: return dense_rows<5>(packed, bias, x, x_stride, y, y_stride, in, out);
    case 6: return dense_rows<6>(packed, bias, x, x_stride, y, y_stride, in, out);
    case 7: return dense_rows<7>(packed, bias, x, x_stride, y, y_stride, in, out);
    default: return dense_rows<8>(packed, bias, x, x_stride, y, y_stride, in, out);
  }
}

}  // namespace

void Mlp::forward(const float* in, float* out, float* scratch, int rows) const {
  const int w = max_width();
  float* buf[2] = {scratch, scratch + static_cast<size_t>(w) * kMlpMaxRows};
  const float* x = in;
  int x_stride = input_dim();
  for (size_t k = 0; k < layers.size(); ++k) {
    const Layer& l = layers[k];
    const bool last = k + 1 == layers.size();
    float* y = last ? out : buf[k % 2];
    const int y_stride = last ? l.out : w;
    dense_forward(l.packed.data(), l.bias.data(), x, x_stride, y, y_stride, l.in, l.out, rows);
    if (!last)
      for (int r = 0; r < rows; ++r)
        for (int i = 0; i < l.out; ++i) y[r * y_stride + i] = elu(y[r * y_stride + i]);
    x = y;
    x_stride = y_stride;
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
  s.a.assign(static_cast<size_t>(2 * w) * kMlpMaxRows, 0.0f);
  s.b.assign(static_cast<size_t>(std::max(state_dim(), pose_dim())), 0.0f);
  s.state.assign(static_cast<size_t>(kCompressedMaxFrames + 1) * state_dim(), 0.0f);
  s.pose_input.assign(static_cast<size_t>(kMlpMaxRows) * state_dim(), 0.0f);
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
  decode_rows(state, pose, 1, scratch);
}

void CompressedModel::decode_rows(const float* states, float* poses, int rows, CompressedScratch& scratch) const {
  const int S = state_dim(), P = pose_dim();
  for (int r0 = 0; r0 < rows; r0 += kMlpMaxRows) {
    const int n = std::min(kMlpMaxRows, rows - r0);
    float* in = scratch.pose_input.data();
    for (int r = 0; r < n; ++r) {
      const float* state = states + static_cast<size_t>(r0 + r) * S;
      for (int k = 0; k < kFeatureDim; ++k) in[r * S + k] = state[k];
      for (int k = 0; k < latent; ++k) in[r * S + kFeatureDim + k] = state[kFeatureDim + k] * z_std[k] + z_mean[k];
    }
    float* out = poses + static_cast<size_t>(r0) * P;
    decompressor.forward(in, out, scratch.a.data(), n);
    for (int r = 0; r < n; ++r) {
      float* pose = out + static_cast<size_t>(r) * P;
      for (int k = 0; k < P; ++k) pose[k] = pose[k] * y_std[k] + y_mean[k];
      for (size_t j = 0; j < fixed_joints.size(); ++j)
        if (fixed_joints[j])
          for (int c = 0; c < 3; ++c) pose[6 * num_joints + 3 * j + c] = fixed_translations[3 * j + c];
    }
  }
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
  return compressed_decision(model, current, query, 1, transition_cost, nullptr, projected, cost, scratch);
}

bool compressed_decision(const CompressedModel& model, const float* current, const float* queries, int n,
                         float transition_cost, const CandidateFilter* filter, float* projected, float* cost,
                         CompressedScratch& scratch) {
  if (n < 1 || n > kMlpMaxRows)
    throw std::invalid_argument("compressed_decision: 1.." + std::to_string(kMlpMaxRows) + " queries, got " +
                                std::to_string(n));
  const int S = model.state_dim();
  float* states = scratch.state.data();  // n x S (playback reuses it afterwards)
  model.projector.forward(queries, states, scratch.a.data(), n);
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (const CandidateFilter* f = filter;; f = f->fallback()) {
    const float stay = filtered_state_cost(feature_distance(queries, current), f, current);
    float best = kInf;
    int arg = 0;
    for (int r = 0; r < n; ++r) {
      const float* p = states + static_cast<size_t>(r) * S;
      const float c = filtered_state_cost(feature_distance(queries, p), f, p);
      if (c < best) best = c, arg = r;
    }
    if (stay < kInf || best < kInf || f == nullptr) {
      std::copy(states + static_cast<size_t>(arg) * S, states + static_cast<size_t>(arg + 1) * S, projected);
      const bool transition = best + transition_cost < stay;
      if (cost) *cost = transition ? best : stay;
      return transition;
    }
  }
}

void compressed_playback(const CompressedModel& model, const float* start, int frames, float* rows, float* end,
                         CompressedScratch& scratch) {
  if (frames < 0 || frames > kCompressedMaxFrames)
    throw std::invalid_argument("compressed_playback: frames must be in 0.." + std::to_string(kCompressedMaxFrames));
  // Every state first (the stepper's weights stay in cache), then their poses in batches.
  float* states = scratch.state.data();
  const int S = model.state_dim();
  std::copy(start, start + S, states);
  for (int k = 1; k <= frames; ++k) {
    std::copy(states + (k - 1) * S, states + k * S, states + k * S);
    model.step(states + static_cast<size_t>(k) * S, scratch);
  }
  model.decode_rows(states, rows, frames + 1, scratch);
  std::copy(states + static_cast<size_t>(frames) * S, states + static_cast<size_t>(frames + 1) * S, end);
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
