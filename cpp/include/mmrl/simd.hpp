// The library's vector kernels' shared pieces: 8-float lanes (GCC/Clang vector extensions)
// and the AVX2/baseline function clones. Every kernel built from them runs the same IEEE
// operations in the same order in every clone (-ffp-contract=off, CMakeLists.txt), so a
// result never depends on the CPU.
#pragma once

#include <cstdint>
#include <cstring>
#include <type_traits>

// Hot entry points (the search, the networks' dense layers) are compiled twice on x86-64 Linux
// with GCC, for AVX2 and for the baseline, and the loader picks one per CPU (function
// multiversioning; `flatten` inlines the whole kernel into each clone): a portable build runs
// the 8-lane kernels in AVX registers where the CPU has them. MMRL_NO_CLONES disables it.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__) && \
    !defined(MMRL_NO_CLONES) && !defined(__AVX2__)
#define MMRL_MULTIVERSION __attribute__((target_clones("avx2", "default"), flatten))
#else
#define MMRL_MULTIVERSION
#endif

namespace mmrl {

// kLanes floats processed together. The compiler maps them to AVX/SSE/NEON registers (or
// scalar code), with the same per-lane operations everywhere.
constexpr int kLanes = 8;
typedef float Lanes __attribute__((vector_size(kLanes * sizeof(float))));
typedef int32_t LaneMask __attribute__((vector_size(kLanes * sizeof(float))));

// Always inlined: a Lanes value never crosses a call, so the AVX2 and baseline clones never
// disagree on how it is passed.
__attribute__((always_inline)) inline Lanes load_lanes(const float* p) {
  Lanes v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}

__attribute__((always_inline)) inline void store_lanes(float* p, Lanes v) { std::memcpy(p, &v, sizeof(v)); }

// f(std::integral_constant<int, N>{}) with N = n (1..8; more counts as 8): the one place a
// run-time count becomes a kernel's template argument (its accumulators then stay in registers).
template <class F>
__attribute__((always_inline)) inline void with_count_1_to_8(int n, F&& f) {
  switch (n) {
    case 1: return f(std::integral_constant<int, 1>{});
    case 2: return f(std::integral_constant<int, 2>{});
    case 3: return f(std::integral_constant<int, 3>{});
    case 4: return f(std::integral_constant<int, 4>{});
    case 5: return f(std::integral_constant<int, 5>{});
    case 6: return f(std::integral_constant<int, 6>{});
    case 7: return f(std::integral_constant<int, 7>{});
    default: return f(std::integral_constant<int, 8>{});
  }
}

}  // namespace mmrl
