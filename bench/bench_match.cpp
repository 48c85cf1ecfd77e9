// Single-query latency and build time of motion matching on real feature rows:
// our Matcher (KD-tree) vs our brute force vs nanoflann, same rows, same queries.
//
// Rows: the normalized features of all shared BVH data (149k frames); N = 10k and 70k are
// prefixes, 150k is all of it, 300k adds the mirrored copies. Only valid frames are
// searched (nanoflann gets the same valid rows, compacted).
// Query sets, noise in units of the per-dimension std of the normalized features:
//   near    a database row + 0.05 std
//   policy  frame i's pose part [0:15] with frame j's trajectory part [15:27], + 0.5 std
//   far     frame i's pose part with the trajectory part uniform in mean +- 3 std
// "ours+bound" starts from frame i + 1 (the continuation), as the controller does.
// Each benchmark also reports median_ns: the median over the 1024 queries of one query's time.
#include <benchmark/benchmark.h>
#include <nanoflann.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "mmrl/bvh.hpp"
#include "mmrl/database.hpp"
#include "mmrl/search.hpp"

namespace {

constexpr int kDim = 27;
constexpr int kNumQueries = 1024;
const char* kSetNames[3] = {"near", "policy", "far"};

struct Rows {
  std::vector<float> x;  // N x 27 normalized
  std::vector<uint8_t> valid;
  int64_t n = 0;
};

// All clips of the shared data, loaded once; database rows with or without mirroring.
const Rows& shared_rows(bool mirror) {
  static std::map<bool, Rows> cache;
  auto it = cache.find(mirror);
  if (it != cache.end()) return it->second;
  static std::vector<mmrl::Motion> clips;
  if (clips.empty()) {
    std::vector<std::string> files;
    for (const auto& e : std::filesystem::recursive_directory_iterator(MMRL_SHARED_DATA))
      if (e.path().extension() == ".bvh") files.push_back(e.path().string());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) clips.push_back(mmrl::bvh_load(f));
  }
  mmrl::DatabaseOptions opts;
  opts.mirror = mirror;
  const mmrl::Database db = mmrl::database_build(clips, opts);
  Rows r;
  r.x.assign(db.normalized.begin(), db.normalized.end());
  r.valid = db.valid;
  r.n = db.num_frames;
  return cache[mirror] = std::move(r);
}

// A prefix of the shared rows: n <= 149k uses the plain database, larger n the mirrored one.
struct Dataset {
  Rows rows;
  std::vector<float> queries[3];
  std::vector<int64_t> bounds[3];
};

const Dataset& dataset(int64_t n) {
  static std::map<int64_t, std::unique_ptr<Dataset>> cache;
  auto& slot = cache[n];
  if (slot) return *slot;
  const Rows& all = shared_rows(n > 160000);
  auto ds = std::make_unique<Dataset>();
  Rows& r = ds->rows;
  r.n = std::min(n, all.n);
  r.x.assign(all.x.begin(), all.x.begin() + r.n * kDim);
  r.valid.assign(all.valid.begin(), all.valid.begin() + r.n);
  std::vector<double> mean(kDim, 0.0), sd(kDim, 0.0);
  for (int64_t i = 0; i < r.n; ++i)
    for (int d = 0; d < kDim; ++d) mean[d] += r.x[i * kDim + d] / r.n;
  for (int64_t i = 0; i < r.n; ++i)
    for (int d = 0; d < kDim; ++d) sd[d] += (r.x[i * kDim + d] - mean[d]) * (r.x[i * kDim + d] - mean[d]) / r.n;
  for (auto& s : sd) s = std::sqrt(s);
  std::mt19937 rng(42);
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::uniform_int_distribution<int64_t> row(0, r.n - 2);
  for (int s = 0; s < 3; ++s) {
    auto& q = ds->queries[s];
    q.resize(kNumQueries * kDim);
    for (int k = 0; k < kNumQueries; ++k) {
      const int64_t i = row(rng), j = row(rng);
      ds->bounds[s].push_back(i + 1);
      for (int d = 0; d < kDim; ++d) {
        const float xi = r.x[i * kDim + d], xj = r.x[j * kDim + d];
        double v;
        if (s == 0) v = xi + 0.05 * sd[d] * g(rng);
        else if (s == 1) v = (d < 15 ? xi : xj) + 0.5 * sd[d] * g(rng);
        else v = d < 15 ? xi : mean[d] + u(rng) * sd[d];
        q[k * kDim + d] = static_cast<float>(v);
      }
    }
  }
  slot = std::move(ds);
  return *slot;
}

// Runs fn(query, bound) over the query set, one query per iteration, then times each query
// once more to report the median.
template <class Fn>
void run_queries(benchmark::State& state, const Dataset& ds, int set, Fn&& fn) {
  const auto& q = ds.queries[set];
  const auto& b = ds.bounds[set];
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(fn(q.data() + k * kDim, b[k]));
    k = (k + 1) % kNumQueries;
  }
  std::vector<double> t(kNumQueries);
  for (int i = 0; i < kNumQueries; ++i) {
    const auto a = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(fn(q.data() + i * kDim, b[i]));
    t[i] = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - a).count();
  }
  std::nth_element(t.begin(), t.begin() + kNumQueries / 2, t.end());
  state.counters["median_ns"] = t[kNumQueries / 2];
  state.counters["rows"] = static_cast<double>(ds.rows.n);
  state.SetLabel(kSetNames[set]);
}

// ---- ours --------------------------------------------------------------------------------
std::unique_ptr<mmrl::Matcher> make_matcher(const Dataset& ds, int leaf, bool scan) {
  mmrl::MatcherOptions o;
  o.leaf_size = leaf;
  o.brute_force_below = scan ? (int64_t{1} << 40) : 0;
  return std::make_unique<mmrl::Matcher>(ds.rows.x.data(), ds.rows.n, kDim, ds.rows.valid.data(), o);
}

void BM_Ours(benchmark::State& state) {
  const Dataset& ds = dataset(state.range(0));
  auto m = make_matcher(ds, static_cast<int>(state.range(2)), false);
  run_queries(state, ds, static_cast<int>(state.range(1)), [&](const float* q, int64_t) { return m->match(q); });
}

void BM_OursBound(benchmark::State& state) {
  const Dataset& ds = dataset(state.range(0));
  auto m = make_matcher(ds, static_cast<int>(state.range(2)), false);
  run_queries(state, ds, static_cast<int>(state.range(1)),
              [&](const float* q, int64_t b) { return m->match(q, 0, 0, b); });
}

// Our brute force: the blocked, vectorized scan (one leaf holding every valid row).
void BM_BruteForce(benchmark::State& state) {
  const Dataset& ds = dataset(state.range(0));
  auto m = make_matcher(ds, 16, true);
  run_queries(state, ds, static_cast<int>(state.range(1)), [&](const float* q, int64_t) { return m->match(q); });
}

// ---- nanoflann (peer) ---------------------------------------------------------------------
struct ValidRows {
  std::vector<float> x;  // compacted valid rows
  int64_t n = 0;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(n); }
  float kdtree_get_pt(size_t i, size_t d) const { return x[i * kDim + d]; }
  template <class B>
  bool kdtree_get_bbox(B&) const { return false; }
};
using NanoTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, ValidRows>, ValidRows, kDim,
                                                     uint32_t>;

std::unique_ptr<ValidRows> valid_rows(const Dataset& ds) {
  auto v = std::make_unique<ValidRows>();
  for (int64_t i = 0; i < ds.rows.n; ++i)
    if (ds.rows.valid[i]) {
      v->x.insert(v->x.end(), ds.rows.x.begin() + i * kDim, ds.rows.x.begin() + (i + 1) * kDim);
      ++v->n;
    }
  return v;
}

void BM_Nanoflann(benchmark::State& state) {
  const Dataset& ds = dataset(state.range(0));
  auto rows = valid_rows(ds);
  NanoTree tree(kDim, *rows, nanoflann::KDTreeSingleIndexAdaptorParams(static_cast<size_t>(state.range(2))));
  run_queries(state, ds, static_cast<int>(state.range(1)), [&](const float* q, int64_t) {
    uint32_t idx;
    float d;
    tree.knnSearch(q, 1, &idx, &d);
    return idx;
  });
}

// ---- build time ---------------------------------------------------------------------------
void BM_BuildOurs(benchmark::State& state) {
  const Dataset& ds = dataset(state.range(0));
  for (auto _ : state) benchmark::DoNotOptimize(make_matcher(ds, static_cast<int>(state.range(1)), false));
  state.counters["rows"] = static_cast<double>(ds.rows.n);
}

void BM_BuildNanoflann(benchmark::State& state) {
  const Dataset& ds = dataset(state.range(0));
  auto rows = valid_rows(ds);
  for (auto _ : state) {
    NanoTree tree(kDim, *rows, nanoflann::KDTreeSingleIndexAdaptorParams(static_cast<size_t>(state.range(1))));
    benchmark::DoNotOptimize(&tree);
  }
  state.counters["rows"] = static_cast<double>(ds.rows.n);
}

const std::vector<int64_t> kSizes = {10000, 70000, 150000, 300000};

void query_args(benchmark::internal::Benchmark* b) {
  for (int64_t n : kSizes)
    for (int s = 0; s < 3; ++s) b->Args({n, s, 16});
}
void leaf_sweep(benchmark::internal::Benchmark* b) {
  for (int s = 0; s < 3; ++s)
    for (int leaf : {4, 8, 16, 32, 64, 128}) b->Args({150000, s, leaf});
}
void nanoflann_args(benchmark::internal::Benchmark* b) {
  for (int64_t n : kSizes)
    for (int s = 0; s < 3; ++s) b->Args({n, s, 10});  // nanoflann's default leaf size
}
void build_args(benchmark::internal::Benchmark* b) {
  for (int64_t n : kSizes) b->Args({n, 16});
}

}  // namespace

BENCHMARK(BM_Ours)->Apply(query_args)->ArgNames({"n", "set", "leaf"});
BENCHMARK(BM_OursBound)->Apply(query_args)->ArgNames({"n", "set", "leaf"});
BENCHMARK(BM_BruteForce)->Apply(query_args)->ArgNames({"n", "set", "leaf"});
BENCHMARK(BM_Nanoflann)->Apply(nanoflann_args)->ArgNames({"n", "set", "leaf"});
BENCHMARK(BM_Ours)->Name("BM_OursLeafSweep")->Apply(leaf_sweep)->ArgNames({"n", "set", "leaf"});
BENCHMARK(BM_BuildOurs)->Apply(build_args)->ArgNames({"n", "leaf"})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BuildNanoflann)->Apply(build_args)->ArgNames({"n", "leaf"})->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
