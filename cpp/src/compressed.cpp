#include "mmrl/compressed.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <type_traits>

#include "mmrl/kdtree.hpp"
#include "mmrl/search.hpp"
#include "mmrl/simd.hpp"

#if defined(__x86_64__)
#include <cpuid.h>
#include <immintrin.h>
#endif

namespace mmrl {

static_assert(kMlpMaxRows == 8, "with_count_1_to_8 (simd.hpp) covers 1..8 rows");

namespace {

// ELU over n floats in place: x for x > 0, expm1(x) otherwise, 8 lanes at a time. expm1(x) =
// 2^k (expm1(r) + 1) - 1 with x = k ln2 + r, |r| <= ln2 / 2, and expm1(r) by its Taylor series
// to r^8 / 8! (relative error under 1e-7 on that range; near 0, k = 0 and the series is expm1
// itself). Only IEEE adds, multiplies and conversions, so both clones give the same bits.
MMRL_MULTIVERSION void elu_inplace(float* y, int n) {
  typedef int32_t Ints __attribute__((vector_size(kLanes * sizeof(int32_t))));
  const int full = n - n % kLanes;
  auto lanes_elu = [](Lanes x) {
    const Lanes xc = x < Lanes{} ? x : Lanes{};  // the positive lanes are taken as they are
    const Lanes lo = xc < -87.0f ? Lanes{} - 87.0f : xc;  // 2^k stays normal; expm1 is -1 there in float
    const Lanes t = lo * 1.44269504088896341f - 0.5f;  // k = round(lo / ln2), lo <= 0
    Ints k = __builtin_convertvector(t, Ints);  // truncation toward zero of t
    k = k - (__builtin_convertvector(k, Lanes) > t ? Ints{} + 1 : Ints{});  // floor(t)
    k = k + 1;
    const Lanes kf = __builtin_convertvector(k, Lanes);
    const Lanes r = (lo - kf * 0.693145751953125f) - kf * 1.428606765330187e-06f;  // Cody-Waite ln2
    Lanes p = Lanes{} + 2.48015873015873e-05f;                                     // 1/8!
    p = p * r + 1.98412698412698e-04f;
    p = p * r + 1.38888888888889e-03f;
    p = p * r + 8.33333333333333e-03f;
    p = p * r + 4.16666666666667e-02f;
    p = p * r + 1.66666666666667e-01f;
    p = p * r + 0.5f;
    const Lanes em1 = (p * r) * r + r;  // expm1(r)
    Lanes two_k;
    const Ints bits = (k + 127) << 23;
    std::memcpy(&two_k, &bits, sizeof(two_k));
    const Lanes e = two_k * em1 + (two_k - 1.0f);
    return x > Lanes{} ? x : (x == x ? e : x);  // NaN stays NaN, as std::expm1 keeps it
  };
  for (int i = 0; i < full; i += kLanes) {
    Lanes x;
    std::memcpy(&x, y + i, sizeof(x));
    x = lanes_elu(x);
    std::memcpy(y + i, &x, sizeof(x));
  }
  if (full < n) {
    float tmp[kLanes] = {};
    std::copy(y + full, y + n, tmp);
    Lanes x;
    std::memcpy(&x, tmp, sizeof(x));
    x = lanes_elu(x);
    std::memcpy(tmp, &x, sizeof(x));
    std::copy(tmp, tmp + (n - full), y + full);
  }
}

void check_size(const std::vector<float>& v, size_t n, const std::string& what) {
  if (v.size() != n)
    throw std::invalid_argument(what + ": expected " + std::to_string(n) + " floats, got " + std::to_string(v.size()));
}

size_t packed_size(const Mlp::Layer& l) {
  return static_cast<size_t>((l.out + kLanes - 1) / kLanes) * l.in * kLanes;
}

constexpr float kHalfMax = 65504.0f;

// IEEE float16 bits of a finite float (|f| <= kHalfMax), rounded to nearest even; widen() of
// them is exact, so both clones read the same weights.
uint16_t float_to_half(float f) {
  uint32_t x;
  std::memcpy(&x, &f, 4);
  const uint32_t sign = (x >> 16) & 0x8000u, ax = x & 0x7fffffffu;
  if (ax < 0x33000001u) return static_cast<uint16_t>(sign);  // below half the smallest subnormal: 0
  if (ax < 0x38800000u) {                                     // a subnormal half
    const int shift = 126 - static_cast<int>(ax >> 23);       // 14 .. 24
    const uint32_t m = (ax & 0x7fffffu) | 0x800000u;
    uint32_t h = m >> shift;
    const uint32_t rem = m & ((1u << shift) - 1), half = 1u << (shift - 1);
    if (rem > half || (rem == half && (h & 1u))) ++h;
    return static_cast<uint16_t>(sign | h);
  }
  uint32_t h = ((ax - 0x38000000u) >> 13);  // rebias the exponent (127 -> 15), keep 10 bits
  const uint32_t rem = ax & 0x1fffu;
  if (rem > 0x1000u || (rem == 0x1000u && (h & 1u))) ++h;
  return static_cast<uint16_t>(sign | h);
}

}  // namespace

int Mlp::max_width() const {
  int w = 0;
  for (const Layer& l : layers) w = std::max({w, l.in, l.out});
  return w;
}

size_t Mlp::num_parameters() const {
  size_t n = 0;
  for (const Layer& l : layers) n += static_cast<size_t>(l.in) * l.out + l.bias.size();
  return n;
}

size_t Mlp::memory_bytes() const {
  size_t n = 0;
  for (const Layer& l : layers)
    n += sizeof(float) * (l.weight.size() + l.bias.size()) + sizeof(uint16_t) * l.packed.size();
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
    if (!(l.weight.empty() && l.packed.size() == packed_size(l))) {  // not packed yet
      check_size(l.weight, static_cast<size_t>(l.in) * l.out, name + " weight");
      for (float v : l.weight)
        if (!std::isfinite(v)) throw std::invalid_argument(name + ": weight is not finite");
    }
    for (float v : l.weight)
      if (!(std::abs(v) <= kHalfMax))
        throw std::invalid_argument(name + ": a weight (" + std::to_string(v) + ") is beyond float16's range (65504)");
    check_size(l.bias, static_cast<size_t>(l.out), name + " bias");
    for (float v : l.bias)
      if (!std::isfinite(v)) throw std::invalid_argument(name + ": bias is not finite");
  }
}

void Mlp::pack() {
  check("network");  // every layer fits before any is packed: pack() changes all or nothing
  for (Layer& l : layers) {
    if (l.weight.empty() && l.packed.size() == packed_size(l)) continue;  // packed already
    std::vector<uint16_t> packed(packed_size(l), 0);
    for (int o = 0; o < l.out; ++o)
      for (int i = 0; i < l.in; ++i) {
        const float w = l.weight[static_cast<size_t>(o) * l.in + i];
        packed[(static_cast<size_t>(o / kLanes) * l.in + i) * kLanes + o % kLanes] = float_to_half(w);
      }
    l.packed = std::move(packed);
    l.weight.clear();
    l.weight.shrink_to_fit();
  }
}

namespace {

// 8 float16 weights widened to float32, exactly (finite halves; pack refuses the rest), with
// integer and float vector operations only, so the AVX2 clone and the baseline give the same
// bits as F16C's conversion.
__attribute__((always_inline)) inline Lanes widen(const uint16_t* p) {
  typedef uint16_t Shorts __attribute__((vector_size(kLanes * sizeof(uint16_t))));
  typedef uint32_t Words __attribute__((vector_size(kLanes * sizeof(uint32_t))));
  Shorts h;
  std::memcpy(&h, p, sizeof(h));
  typedef int32_t Ints __attribute__((vector_size(kLanes * sizeof(int32_t))));
  const Words w = __builtin_convertvector(h, Words);
  // A normal half: its exponent rebiased (15 -> 127) by an integer add. A subnormal (exponent
  // bits 0): mantissa x 2^-24, exact in float32 and no subnormal operand (DAZ cannot change it).
  const Words normal = ((w & 0x7fffu) << 13) + (112u << 23);
  const Lanes tiny = __builtin_convertvector(__builtin_convertvector(w & 0x3ffu, Ints), Lanes) * 5.9604644775390625e-08f;
  Words tiny_bits;
  std::memcpy(&tiny_bits, &tiny, sizeof(tiny_bits));
  const Words bits = ((w & 0x7c00u) == 0u ? tiny_bits : normal) | ((w & 0x8000u) << 16);
  Lanes f;
  std::memcpy(&f, &bits, sizeof(f));
  return f;
}

// Y = X W^T + b for R rows of X (R <= kMaxRows) over packed weights: per block of 8 outputs, one
// load of each input's weights feeds every row (R independent sums, so the adds pipeline and a
// batch reads the weights once). Each output sums its inputs in order from 0, then adds its bias,
// whatever R is: a row's result does not depend on the batch it is in.
template <int R>
__attribute__((always_inline)) inline void dense_rows(const uint16_t* packed, const float* bias, const float* x,
                                                      int x_stride, float* y, int y_stride, int in, int out) {
  const int blocks = (out + kLanes - 1) / kLanes;
  for (int b = 0; b < blocks; ++b) {
    const uint16_t* w = packed + static_cast<size_t>(b) * in * kLanes;
    Lanes acc[R];
    for (int r = 0; r < R; ++r) acc[r] = Lanes{};
    for (int i = 0; i < in; ++i) {
      const Lanes wi = widen(w + i * kLanes);
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


MMRL_MULTIVERSION void dense_widening(const uint16_t* packed, const float* bias, const float* x, int x_stride,
                                      float* y, int y_stride, int in, int out, int rows) {
  with_count_1_to_8(rows, [&](auto r) { dense_rows<decltype(r)::value>(packed, bias, x, x_stride, y, y_stride, in, out); });
}

#if defined(__x86_64__) && defined(__GNUC__) && !defined(MMRL_NO_CLONES)
#define MMRL_HAS_F16C_KERNEL 1
// dense_rows with F16C's conversion (one vcvtph2ps per 8 weights): the same sums in the same
// order as the widening kernel, so the same bits (the conversion is exact either way).
template <int R>
__attribute__((target("avx2,f16c"))) void dense_rows_f16c(const uint16_t* packed, const float* bias, const float* x,
                                                          int x_stride, float* y, int y_stride, int in, int out) {
  const int blocks = (out + kLanes - 1) / kLanes;
  for (int b = 0; b < blocks; ++b) {
    const uint16_t* w = packed + static_cast<size_t>(b) * in * kLanes;
    __m256 acc[R];
    for (int r = 0; r < R; ++r) acc[r] = _mm256_setzero_ps();
    for (int i = 0; i < in; ++i) {
      const __m256 wi = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(w + i * kLanes)));
      for (int r = 0; r < R; ++r) acc[r] = _mm256_add_ps(acc[r], _mm256_mul_ps(_mm256_set1_ps(x[r * x_stride + i]), wi));
    }
    const int n = std::min(kLanes, out - b * kLanes);
    for (int r = 0; r < R; ++r) {
      float tmp[kLanes];
      _mm256_storeu_ps(tmp, acc[r]);
      for (int l = 0; l < n; ++l) y[r * y_stride + b * kLanes + l] = tmp[l] + bias[b * kLanes + l];
    }
  }
}

#endif

// Whether the F16C kernel runs (chosen once). MMRL_NO_F16C (any value) keeps to the widening
// kernel: for the test that both agree.
bool use_f16c() {
#ifdef MMRL_HAS_F16C_KERNEL
  static const bool f16c = [] {
    __builtin_cpu_init();
    // F16C from CPUID leaf 1 (ECX bit 29): not every compiler's __builtin_cpu_supports names it.
    unsigned a = 0, b = 0, c = 0, d = 0;
    const bool has_f16c = __get_cpuid(1, &a, &b, &c, &d) && (c & (1u << 29)) != 0;
    return __builtin_cpu_supports("avx2") && has_f16c && std::getenv("MMRL_NO_F16C") == nullptr;
  }();
  return f16c;
#else
  return false;
#endif
}

// Y = X W^T + b: the F16C kernel where the CPU has it, else the widening one.
void dense_forward(const uint16_t* packed, const float* bias, const float* x, int x_stride, float* y, int y_stride,
                   int in, int out, int rows) {
#ifdef MMRL_HAS_F16C_KERNEL
  if (use_f16c())
    return with_count_1_to_8(rows, [&](auto r) {
      dense_rows_f16c<decltype(r)::value>(packed, bias, x, x_stride, y, y_stride, in, out);
    });
#endif
  dense_widening(packed, bias, x, x_stride, y, y_stride, in, out, rows);
}

}  // namespace

float float16_to_float(uint16_t h) {
  const uint32_t sign = static_cast<uint32_t>(h & 0x8000u) << 16, e = (h >> 10) & 0x1fu, m = h & 0x3ffu;
  uint32_t bits;
  if (e == 0) {
    const float f = static_cast<float>(m) * 5.9604644775390625e-08f;  // m x 2^-24
    std::memcpy(&bits, &f, 4);
  } else {
    bits = (e == 31 ? 0x7f800000u | (m << 13) : ((e + 112u) << 23) | (m << 13));
  }
  bits |= sign;
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

const char* mlp_kernel() { return use_f16c() ? "f16c" : "widening"; }

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
      for (int r = 0; r < rows; ++r) elu_inplace(y + static_cast<size_t>(r) * y_stride, l.out);
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
      if (!l.weight.empty() || l.packed.size() != packed_size(l)) return false;
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
  return decompressor.memory_bytes() + stepper.memory_bytes() + projector.memory_bytes() +
         sizeof(float) * (y_mean.size() + y_std.size() + z_mean.size() + z_std.size() + fixed_translations.size()) +
         fixed_joints.size();
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
    const float stay = filtered_cost(feature_distance(queries, current), f, Candidate{-1, current});
    float best = kInf;
    int arg = 0;
    for (int r = 0; r < n; ++r) {
      const float* p = states + static_cast<size_t>(r) * S;
      const float c = filtered_cost(feature_distance(queries, p), f, Candidate{-1, p});
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
