// Matcher == brute_force_match exactly: masks, exclude windows, continuation bounds, batches.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "mmrl/search.hpp"

namespace {

// Smooth random walks: consecutive rows are close, like frames of motion clips.
std::vector<float> walk_rows(int64_t n, int dim, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<float> p(static_cast<size_t>(n * dim));
  std::vector<float> x(dim, 0.0f);
  for (int64_t i = 0; i < n; ++i) {
    if (i % 500 == 0)
      for (auto& v : x) v = g(rng);
    for (int d = 0; d < dim; ++d) {
      x[d] = 0.98f * x[d] + 0.1f * g(rng);
      p[i * dim + d] = x[d];
    }
  }
  return p;
}

struct Case {
  std::vector<float> queries;
  std::vector<int64_t> lo, hi, bound;
};

Case make_queries(const std::vector<float>& rows, int64_t n, int dim, int m, float noise, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  Case c;
  c.queries.resize(static_cast<size_t>(m) * dim);
  for (int q = 0; q < m; ++q) {
    const int64_t row = std::uniform_int_distribution<int64_t>(0, n - 2)(rng);
    for (int d = 0; d < dim; ++d) c.queries[q * dim + d] = rows[row * dim + d] + noise * g(rng);
    c.lo.push_back(std::max<int64_t>(0, row - 20));
    c.hi.push_back(std::min<int64_t>(n, row + 20));
    c.bound.push_back(q % 3 == 0 ? -1 : row + 1);
  }
  return c;
}

void expect_matcher_equals_brute_force(int64_t n, int dim, const std::vector<uint8_t>& valid, int leaf,
                                       int64_t brute_below) {
  const auto rows = walk_rows(n, dim, static_cast<uint32_t>(n + dim));
  mmrl::MatcherOptions opts;
  opts.leaf_size = leaf;
  opts.brute_force_below = brute_below;
  mmrl::Matcher matcher(rows.data(), n, dim, valid.data(), opts);
  mmrl::ThreadPool pool(2);
  for (float noise : {0.0f, 0.05f, 0.5f, 2.0f}) {
    const int m = 200;
    Case c = make_queries(rows, n, dim, m, noise, 17);
    std::vector<int64_t> ti(m), bi(m);
    std::vector<float> tc(m), bc(m);
    // With windows and bounds.
    matcher.match_batch(c.queries.data(), m, ti.data(), tc.data(), pool, c.lo.data(), c.hi.data(), c.bound.data());
    matcher.brute_force_batch(c.queries.data(), m, bi.data(), bc.data(), pool, c.lo.data(), c.hi.data(),
                              c.bound.data());
    for (int q = 0; q < m; ++q) {
      ASSERT_EQ(ti[q], bi[q]) << "noise " << noise << " query " << q;
      ASSERT_EQ(tc[q], bc[q]) << "noise " << noise << " query " << q;
      float single_cost = -1;
      ASSERT_EQ(matcher.match(c.queries.data() + q * dim, c.lo[q], c.hi[q], c.bound[q], &single_cost), ti[q]);
      ASSERT_EQ(single_cost, tc[q]);
    }
    // Plain nearest valid row.
    matcher.match_batch(c.queries.data(), m, ti.data(), tc.data(), pool);
    matcher.brute_force_batch(c.queries.data(), m, bi.data(), bc.data(), pool);
    for (int q = 0; q < m; ++q) {
      ASSERT_EQ(ti[q], bi[q]) << "noise " << noise << " query " << q;
      ASSERT_EQ(tc[q], bc[q]);
      if (ti[q] >= 0) {
        ASSERT_TRUE(valid[ti[q]]);
      }
    }
  }
}

TEST(Matcher, EqualsBruteForceWithMasksWindowsAndBounds) {
  for (int64_t n : {2, 17, 1000, 20000})
    for (int dim : {5, 27}) {
      std::mt19937 rng(static_cast<uint32_t>(n));
      std::vector<uint8_t> valid(n);
      for (auto& v : valid) v = (rng() % 10) != 0;
      for (int leaf : {4, 16, 64}) {
        expect_matcher_equals_brute_force(n, dim, valid, leaf, 0);
        expect_matcher_equals_brute_force(n, dim, valid, leaf, 1 << 30);  // blocked-scan fallback
      }
    }
}

TEST(Matcher, BoundWinsTiesAndNothingValid) {
  const int dim = 3;
  std::vector<float> rows = {0, 0, 0, 1, 1, 1, 1, 1, 1, 2, 2, 2};
  std::vector<uint8_t> valid = {1, 1, 1, 1};
  mmrl::Matcher m(rows.data(), 4, dim, valid.data());
  const float q[3] = {1, 1, 1};
  float cost = -1;
  EXPECT_EQ(m.match(q, 0, 0, -1, &cost), 1);  // rows 1 and 2 tie: lowest index
  EXPECT_EQ(cost, 0.0f);
  EXPECT_EQ(m.match(q, 0, 0, 2, &cost), 2);  // the bound keeps a tie
  EXPECT_EQ(m.match(q, 0, 0, 3, &cost), 1);  // strictly better than the bound
  std::vector<uint8_t> none(4, 0);
  mmrl::Matcher empty(rows.data(), 4, dim, none.data());
  EXPECT_EQ(empty.num_valid(), 0);
  EXPECT_EQ(empty.match(q, 0, 0, -1, &cost), -1);
  EXPECT_TRUE(std::isinf(cost));
  EXPECT_EQ(empty.match(q, 0, 0, 3, &cost), 3);  // only the bound is left
  EXPECT_EQ(cost, 3.0f);
  EXPECT_EQ(m.match(q, 0, 4, -1, &cost), -1);  // window excludes everything
}

// The transition cost: with a margin, another row replaces the bound only when it is closer
// by more than the margin; the tree answers exactly like a brute-force scan with the same rule.
TEST(Matcher, BoundMarginEqualsBruteForceAndHandComputedCases) {
  const int dim = 3;
  std::vector<float> rows = {0, 0, 0, 1, 1, 1, 1, 1, 1.5f, 2, 2, 2};
  std::vector<uint8_t> valid = {1, 1, 1, 1};
  mmrl::Matcher m(rows.data(), 4, dim, valid.data());
  const float q[3] = {1, 1, 1};
  float cost = -1;
  // Bound row 2 costs 0.25; row 1 costs 0: better by 0.25.
  EXPECT_EQ(m.match(q, 0, 0, 2, &cost, 0.2f), 1);  // 0 < 0.25 - 0.2
  EXPECT_EQ(cost, 0.0f);
  EXPECT_EQ(m.match(q, 0, 0, 2, &cost, 0.3f), 2);  // not better by more than 0.3: the bound stays
  EXPECT_EQ(cost, 0.25f);                          // with its own cost, not cost - margin
  EXPECT_EQ(m.match(q, 0, 0, 2, &cost, 0.25f), 2);  // a tie with the margin keeps the bound
  EXPECT_EQ(m.match(q, 0, 0, -1, &cost, 5.0f), 1);  // no bound: the margin does nothing
  EXPECT_THROW(m.match(q, 0, 0, 2, &cost, -1.0f), std::invalid_argument);

  const int64_t n = 5000;
  const int d = 27;
  const auto walk = walk_rows(n, d, 5);
  std::vector<uint8_t> all(n, 1);
  mmrl::Matcher tree(walk.data(), n, d, all.data());
  for (float margin : {0.0f, 0.1f, 1.0f, 10.0f}) {
    Case c = make_queries(walk, n, d, 300, 0.5f, 23);
    int transitions = 0;
    for (int k = 0; k < 300; ++k) {
      float tc = -1, bc = -2;
      const float* query = c.queries.data() + k * d;
      const int64_t ti = tree.match(query, c.lo[k], c.hi[k], c.bound[k], &tc, margin);
      const int64_t bi = mmrl::brute_force_match(walk.data(), n, d, all.data(), query, c.lo[k], c.hi[k], c.bound[k],
                                                 &bc, margin);
      ASSERT_EQ(ti, bi) << "margin " << margin << " query " << k;
      ASSERT_EQ(tc, bc);
      transitions += (c.bound[k] >= 0 && ti != c.bound[k]);
    }
    if (margin == 10.0f) {
      EXPECT_LT(transitions, 30);  // a large margin keeps most continuations
    }
  }
}

// A candidate filter of per-row extra costs: 0, a positive cost, or refused (+inf, NaN, and
// negative values, which count as 0).
class RowCosts final : public mmrl::CandidateFilter {
 public:
  explicit RowCosts(std::vector<float> costs) : costs_(std::move(costs)) {}
  float extra_cost(const mmrl::Candidate& c) const override { return costs_[static_cast<size_t>(c.row)]; }
  float extra_cost(int64_t row) const { return costs_[static_cast<size_t>(row)]; }

 private:
  std::vector<float> costs_;
};

std::vector<float> random_row_costs(int64_t n, float refused_share, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> costs(static_cast<size_t>(n));
  for (auto& c : costs) {
    const float r = u(rng);
    c = r < refused_share ? (r < refused_share / 2 ? INFINITY : NAN)
        : r < refused_share + 0.3f ? 0.0f
        : r < refused_share + 0.35f ? -1.0f
        : 2.0f * u(rng);
  }
  return costs;
}

TEST(Matcher, CandidateFilterEqualsBruteForceWithTheSameFilter) {
  // The filter refuses rows or adds a cost >= 0, the continuation bound's included: the tree
  // must return exactly what a brute-force scan with the same filter returns, index and cost.
  for (int64_t n : {int64_t{300}, int64_t{5000}}) {
    const int dim = 27;
    const auto rows = walk_rows(n, dim, 7);
    std::vector<uint8_t> valid(static_cast<size_t>(n), 1);
    for (int64_t i = 0; i < n; i += 11) valid[i] = 0;
    for (float refused : {0.0f, 0.2f, 0.9f}) {
      const RowCosts filter(random_row_costs(n, refused, static_cast<uint32_t>(n) + 3));
      mmrl::Matcher matcher(rows.data(), n, dim, valid.data());
      for (float noise : {0.0f, 0.3f, 1.5f}) {
        Case c = make_queries(rows, n, dim, 300, noise, 29);
        int changed = 0;
        for (int q = 0; q < 300; ++q) {
          for (float margin : {0.0f, 0.5f}) {
            const float* query = &c.queries[static_cast<size_t>(q) * dim];
            const int64_t bound = c.bound[q] >= 0 && valid[c.bound[q]] ? c.bound[q] : -1;
            float tree_cost = 0, brute_cost = 0, plain_cost = 0;
            const int64_t t = matcher.match(query, c.lo[q], c.hi[q], bound, &tree_cost, margin, &filter);
            const int64_t b = mmrl::brute_force_match(rows.data(), n, dim, valid.data(), query, c.lo[q], c.hi[q],
                                                      bound, &brute_cost, margin, &filter);
            ASSERT_EQ(t, b) << "n " << n << " refused " << refused << " query " << q;
            ASSERT_EQ(tree_cost, brute_cost);
            if (t >= 0) {  // never a refused row
              const float extra = filter.extra_cost(t);
              ASSERT_TRUE(extra < INFINITY) << t;
            }
            changed += t != matcher.match(query, c.lo[q], c.hi[q], bound, &plain_cost, margin);
          }
          if (refused < 0.5f) {  // k nearest by filtered cost, as a brute-force scan ranks them
            mmrl::SearchFilter f;
            f.allowed = valid.data();
            f.candidates = &filter;
            int64_t ti[5], bi[5];
            float td[5], bd[5];
            const float* query = &c.queries[static_cast<size_t>(q) * dim];
            ASSERT_EQ(matcher.tree().knn(query, 5, ti, td, f),
                      mmrl::brute_force_knn(rows.data(), n, dim, query, 5, bi, bd, f));
            for (int k = 0; k < 5; ++k) ASSERT_EQ(ti[k], bi[k]) << k;
            for (int k = 0; k < 5; ++k) ASSERT_EQ(td[k], bd[k]) << k;
          }
        }
        if (refused > 0) {
          EXPECT_GT(changed, 0) << "the filter never changed a match: the test tests nothing";
        }
      }
    }
  }
}

TEST(Matcher, CandidateFilterHandComputedCases) {
  // Rows on a line: 0, 1, 2, 3; the query at 1.1. Distances 1.21, 0.01, 0.81, 3.61.
  const std::vector<float> rows = {0.0f, 1.0f, 2.0f, 3.0f};
  mmrl::Matcher matcher(rows.data(), 4, 1, nullptr);
  const float q = 1.1f;
  float cost = 0;
  const RowCosts none({0, 0, 0, 0});
  EXPECT_EQ(matcher.match(&q, 0, 0, -1, &cost, 0.0f, &none), 1);
  const RowCosts ban1({0, INFINITY, 0, 0});
  EXPECT_EQ(matcher.match(&q, 0, 0, -1, &cost, 0.0f, &ban1), 2);  // 0.81 < 1.21
  const RowCosts dear2({0, INFINITY, 0.5f, 0});
  EXPECT_EQ(matcher.match(&q, 0, 0, -1, &cost, 0.0f, &dear2), 0);  // 1.31 > 1.21
  EXPECT_FLOAT_EQ(cost, 1.21f);
  // The bound is filtered too: a refused bound is no bound; a dearer bound loses.
  EXPECT_EQ(matcher.match(&q, 0, 0, 1, &cost, 0.0f, &ban1), 2);
  const RowCosts dear_bound({0, 1.0f, 0, 0});
  EXPECT_EQ(matcher.match(&q, 0, 0, 1, &cost, 0.0f, &dear_bound), 2);  // 1.01 > 0.81
  EXPECT_EQ(matcher.match(&q, 0, 0, 1, &cost, 0.3f, &dear_bound), 1);  // 0.81 is not below 1.01 - 0.3
  EXPECT_FLOAT_EQ(cost, 1.01f);
  const RowCosts all({INFINITY, INFINITY, INFINITY, INFINITY});
  EXPECT_EQ(matcher.match(&q, 0, 0, 1, &cost, 0.0f, &all), -1);
}

TEST(Matcher, ShortlistEqualsBruteForceWithTheSameFilter) {
  // The shortlist rule (k nearest by plain distance, re-ranked by filtered cost, the continuation
  // rule on top): the tree's k-NN and the brute-force scan give the same row and cost, bit for bit.
  for (int64_t n : {int64_t{300}, int64_t{5000}}) {
    const int dim = 27;
    const auto rows = walk_rows(n, dim, 11);
    std::vector<uint8_t> valid(static_cast<size_t>(n), 1);
    for (int64_t i = 0; i < n; i += 7) valid[i] = 0;
    mmrl::Matcher matcher(rows.data(), n, dim, valid.data());
    for (float refused : {0.0f, 0.5f, 0.95f}) {
      const RowCosts filter(random_row_costs(n, refused, static_cast<uint32_t>(n) + 17));
      Case c = make_queries(rows, n, dim, 200, 0.5f, 31);
      int differs_from_exact = 0;
      for (int q = 0; q < 200; ++q)
        for (int k : {1, 8, 64, mmrl::kMaxShortlist})
          for (float margin : {0.0f, 0.5f}) {
            const float* query = &c.queries[static_cast<size_t>(q) * dim];
            const int64_t bound = c.bound[q] >= 0 && valid[c.bound[q]] ? c.bound[q] : -1;
            float tree_cost = -1, brute_cost = -2, exact_cost = 0;
            const int64_t t = matcher.match_shortlist(query, k, c.lo[q], c.hi[q], bound, &tree_cost, margin, &filter);
            const int64_t b = mmrl::brute_force_match_shortlist(rows.data(), n, dim, valid.data(), query, k, c.lo[q],
                                                                c.hi[q], bound, &brute_cost, margin, &filter);
            ASSERT_EQ(t, b) << "n " << n << " k " << k << " query " << q;
            ASSERT_EQ(tree_cost, brute_cost);
            if (t >= 0) {
              ASSERT_TRUE(filter.extra_cost(t) < INFINITY);
            }
            // The exact filtered match is never dearer than the shortlist's choice.
            const int64_t e = matcher.match(query, c.lo[q], c.hi[q], bound, &exact_cost, margin, &filter);
            if (t >= 0) {
              ASSERT_GE(e, 0);
              ASSERT_LE(exact_cost, tree_cost);
            }
            differs_from_exact += (t != e);
          }
      if (refused > 0) {
        EXPECT_GT(differs_from_exact, 0) << "the shortlist never mattered: the test tests nothing";
      }
    }
  }
}

TEST(Matcher, ShortlistOfSeveralQueriesEqualsBruteForce) {
  // The union of several queries' k nearest, ranked by distance to the first query: tree and
  // brute force agree bit for bit, and the union can only lower the filtered cost.
  const int64_t n = 4000;
  const int dim = 27;
  const auto rows = walk_rows(n, dim, 13);
  std::vector<uint8_t> valid(static_cast<size_t>(n), 1);
  for (int64_t i = 0; i < n; i += 5) valid[i] = 0;
  mmrl::Matcher matcher(rows.data(), n, dim, valid.data());
  const RowCosts filter(random_row_costs(n, 0.9f, 99));
  Case c = make_queries(rows, n, dim, 150, 0.5f, 37);
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.0f, 0.3f);
  int lowered = 0, differs = 0;
  for (int q = 0; q < 150; ++q)
    for (int nq : {2, 5, mmrl::kMaxShortlistQueries}) {
      std::vector<float> queries(static_cast<size_t>(nq) * dim);
      for (int k = 0; k < nq; ++k)
        for (int d = 0; d < dim; ++d)
          queries[k * dim + d] = c.queries[static_cast<size_t>(q) * dim + d] + (k == 0 ? 0.0f : g(rng));
      const int64_t bound = c.bound[q] >= 0 && valid[c.bound[q]] ? c.bound[q] : -1;
      float tree_cost = -1, brute_cost = -2, one_cost = 0;
      const int other = nq == 2 ? 1 : 8;
      const int64_t t =
          matcher.match_shortlist(queries.data(), 8, c.lo[q], c.hi[q], bound, &tree_cost, 0.3f, &filter, nq, other);
      const int64_t b = mmrl::brute_force_match_shortlist(rows.data(), n, dim, valid.data(), queries.data(), 8,
                                                          c.lo[q], c.hi[q], bound, &brute_cost, 0.3f, &filter, nq,
                                                          other);
      ASSERT_EQ(t, b) << "query " << q << " nq " << nq;
      ASSERT_EQ(tree_cost, brute_cost);
      const int64_t one = matcher.match_shortlist(queries.data(), 8, c.lo[q], c.hi[q], bound, &one_cost, 0.3f, &filter);
      if (one >= 0) {
        ASSERT_GE(t, 0);
        ASSERT_LE(tree_cost, one_cost);
      }
      lowered += t >= 0 && (one < 0 || tree_cost < one_cost);
      differs += t != one;
    }
  EXPECT_GT(lowered, 0) << "the other queries never added a better row: the test tests nothing (" << differs << ")";
  // Rows given ahead of time (the escape table's way): the other queries' nearest rows passed
  // as extra rows decide exactly as the queries themselves, in the tree and the brute force.
  int extra_changed = 0;
  for (int q = 0; q < 150; ++q) {
    const int nq = 5, other = 4;
    std::vector<float> queries(static_cast<size_t>(nq) * dim);
    for (int k = 0; k < nq; ++k)
      for (int d = 0; d < dim; ++d)
        queries[k * dim + d] = c.queries[static_cast<size_t>(q) * dim + d] + (k == 0 ? 0.0f : g(rng));
    mmrl::SearchFilter window;
    window.allowed = valid.data();
    window.exclude_lo = c.lo[q];
    window.exclude_hi = c.hi[q];
    std::vector<int32_t> extra(static_cast<size_t>((nq - 1) * other), -1);
    for (int k = 1; k < nq; ++k) {
      int64_t found[other];
      float d2[other];
      const int m = mmrl::brute_force_knn(rows.data(), n, dim, &queries[k * dim], other, found, d2, window);
      for (int r = 0; r < m; ++r) extra[(k - 1) * other + r] = static_cast<int32_t>(found[r]);
    }
    // Rows the search could never return (invalid, in the window, the bound) and -1 gaps
    // change nothing.
    extra.push_back(-1);
    extra.push_back(0);  // row 0 is not valid (every fifth row is not)
    if (c.hi[q] > c.lo[q]) extra.push_back(static_cast<int32_t>(c.lo[q]));
    if (c.bound[q] >= 0) extra.push_back(static_cast<int32_t>(c.bound[q]));
    const int64_t bound = c.bound[q] >= 0 && valid[c.bound[q]] ? c.bound[q] : -1;
    float by_queries = -1, by_rows = -2, by_brute = -3;
    const int64_t a =
        matcher.match_shortlist(queries.data(), 8, c.lo[q], c.hi[q], bound, &by_queries, 0.3f, &filter, nq, other);
    const int64_t b = matcher.match_shortlist(queries.data(), 8, c.lo[q], c.hi[q], bound, &by_rows, 0.3f, &filter, 1, 1,
                                              extra.data(), static_cast<int>(extra.size()));
    const int64_t e = mmrl::brute_force_match_shortlist(rows.data(), n, dim, valid.data(), queries.data(), 8, c.lo[q],
                                                        c.hi[q], bound, &by_brute, 0.3f, &filter, 1, 1, extra.data(),
                                                        static_cast<int>(extra.size()));
    ASSERT_EQ(a, b) << "query " << q;
    ASSERT_EQ(a, e) << "query " << q;
    ASSERT_EQ(by_queries, by_rows);
    ASSERT_EQ(by_queries, by_brute);
    float alone = 0;
    extra_changed += a != matcher.match_shortlist(queries.data(), 8, c.lo[q], c.hi[q], bound, &alone, 0.3f, &filter);
  }
  EXPECT_GT(extra_changed, 0) << "the extra rows never changed a decision: the test tests nothing";
  const int32_t outside[1] = {static_cast<int32_t>(n)};
  float cost = 0;
  EXPECT_THROW(mmrl::brute_force_match_shortlist(rows.data(), n, dim, valid.data(), c.queries.data(), 8, 0, 0, -1,
                                                 &cost, 0.0f, &filter, 1, 1, outside, 1),
               std::out_of_range);
  EXPECT_THROW(matcher.match_shortlist(c.queries.data(), 8, 0, 0, -1, &cost, 0.0f, &filter, 1, 1, outside,
                                       mmrl::kMaxExtraRows + 1),
               std::invalid_argument);
  EXPECT_THROW(matcher.match_shortlist(c.queries.data(), 8, 0, 0, -1, &cost, 0.0f, &filter, 0), std::invalid_argument);
  EXPECT_THROW(matcher.match_shortlist(c.queries.data(), 8, 0, 0, -1, &cost, 0.0f, &filter,
                                       mmrl::kMaxShortlistQueries + 1),
               std::invalid_argument);
}

TEST(Matcher, ShortlistHandComputedCases) {
  // Rows on a line: 0, 1, 2, 3, 4; the query at 1.1. Plain order: 1, 2, 0, 3, 4.
  const std::vector<float> rows = {0.0f, 1.0f, 2.0f, 3.0f, 4.0f};
  mmrl::Matcher matcher(rows.data(), 5, 1, nullptr);
  const float q = 1.1f;
  float cost = 0;
  const RowCosts ban12({0, INFINITY, INFINITY, 0, 0});
  EXPECT_EQ(matcher.match_shortlist(&q, 2, 0, 0, -1, &cost, 0.0f, &ban12), -1);  // both shortlisted refused
  EXPECT_EQ(matcher.match_shortlist(&q, 3, 0, 0, -1, &cost, 0.0f, &ban12), 0);
  EXPECT_FLOAT_EQ(cost, 1.21f);
  const RowCosts dear1({0, 2.0f, 0, 0, 0});
  EXPECT_EQ(matcher.match_shortlist(&q, 1, 0, 0, -1, &cost, 0.0f, &dear1), 1);  // alone on the list
  EXPECT_FLOAT_EQ(cost, 2.01f);
  EXPECT_EQ(matcher.match_shortlist(&q, 2, 0, 0, -1, &cost, 0.0f, &dear1), 2);  // 0.81 < 2.01
  // The continuation (bound 4, distance 8.41, outside a window that holds only itself) is
  // kept against a shortlist that cannot beat it by the margin.
  const RowCosts none({0, 0, 0, 0, 0});
  EXPECT_EQ(matcher.match_shortlist(&q, 2, 4, 5, 4, &cost, 8.5f, &none), 4);
  EXPECT_FLOAT_EQ(cost, 8.41f);
  EXPECT_EQ(matcher.match_shortlist(&q, 2, 4, 5, 4, &cost, 8.0f, &none), 1);
  EXPECT_THROW(matcher.match_shortlist(&q, 0, 0, 0, -1, &cost, 0.0f, &none), std::invalid_argument);
  EXPECT_THROW(matcher.match_shortlist(&q, mmrl::kMaxShortlist + 1, 0, 0, -1, &cost, 0.0f, &none),
               std::invalid_argument);
}

TEST(Matcher, RefusesBadInput) {
  std::vector<float> rows(30, 0.0f);
  EXPECT_THROW(mmrl::Matcher(nullptr, 10, 3, nullptr), std::invalid_argument);
  EXPECT_THROW(mmrl::Matcher(rows.data(), 10, 0, nullptr), std::invalid_argument);
  EXPECT_THROW(mmrl::Matcher(rows.data(), -1, 3, nullptr), std::invalid_argument);
  mmrl::MatcherOptions bad;
  bad.leaf_size = 0;
  EXPECT_THROW(mmrl::Matcher(rows.data(), 10, 3, nullptr, bad), std::invalid_argument);
  mmrl::Matcher m(rows.data(), 10, 3, nullptr);
  mmrl::ThreadPool pool(2);
  int64_t idx[2];
  float cost[2];
  EXPECT_THROW(m.match(nullptr), std::invalid_argument);
  EXPECT_THROW(m.match(rows.data(), 0, 0, 10), std::out_of_range);
  EXPECT_THROW(m.match_batch(nullptr, 2, idx, cost, pool), std::invalid_argument);
  EXPECT_THROW(m.match_batch(rows.data(), 2, nullptr, cost, pool), std::invalid_argument);
  EXPECT_THROW(m.match_batch(rows.data(), -1, idx, cost, pool), std::invalid_argument);
  const int64_t lo[2] = {0, 0};
  EXPECT_THROW(m.match_batch(rows.data(), 2, idx, cost, pool, lo, nullptr), std::invalid_argument);
  EXPECT_THROW(mmrl::brute_force_match(rows.data(), 10, 3, nullptr, nullptr, 0, 0, -1, cost), std::invalid_argument);
}

// The multiversioned entry points of the public k-NN (serial and across a pool) ==
// brute_force_knn, exactly, and refuse what KDTree::knn refuses.
TEST(KDTreeEntryPoints, EqualBruteForceWithAndWithoutFilters) {
  for (int64_t n : {1, 17, 1000, 20000})
    for (int dim : {2, 27})
      for (int k : {1, 3, 10}) {
        if (k > n) continue;
        const auto rows = walk_rows(n, dim, static_cast<uint32_t>(n * 7 + dim));
        const mmrl::KDTree tree(rows.data(), n, dim, 16);
        std::mt19937 rng(static_cast<uint32_t>(n + k));
        std::vector<uint8_t> allowed(static_cast<size_t>(n));
        for (auto& a : allowed) a = (rng() % 4) != 0;
        mmrl::SearchFilter masked;
        masked.allowed = allowed.data();
        masked.exclude_lo = n / 3;
        masked.exclude_hi = n / 2;
        const int m = 100;
        mmrl::ThreadPool pool(2);
        const Case c = make_queries(rows, std::max<int64_t>(n, 2), dim, m, 0.5f, 5);
        for (const mmrl::SearchFilter& filter : {mmrl::SearchFilter{}, masked}) {
          std::vector<int64_t> batch_idx(static_cast<size_t>(m) * k), one_idx(k), brute_idx(k);
          std::vector<float> batch_d(static_cast<size_t>(m) * k), one_d(k), brute_d(k);
          std::vector<int64_t> pool_idx(batch_idx.size());
          std::vector<float> pool_d(batch_d.size());
          mmrl::kdtree_knn_batch(tree, c.queries.data(), m, k, batch_idx.data(), batch_d.data(), filter);
          mmrl::kdtree_knn_batch(tree, c.queries.data(), m, k, pool_idx.data(), pool_d.data(), pool, filter);
          ASSERT_EQ(pool_idx, batch_idx);
          ASSERT_EQ(pool_d, batch_d);
          for (int q = 0; q < m; ++q) {
            const float* query = c.queries.data() + q * dim;
            const int found = mmrl::kdtree_knn(tree, query, k, one_idx.data(), one_d.data(), filter);
            ASSERT_EQ(found, mmrl::brute_force_knn(rows.data(), n, dim, query, k, brute_idx.data(), brute_d.data(),
                                                   filter));
            for (int j = 0; j < k; ++j) {
              ASSERT_EQ(one_idx[j], brute_idx[j]) << "n=" << n << " dim=" << dim << " k=" << k << " q=" << q;
              ASSERT_EQ(one_d[j], brute_d[j]) << "n=" << n << " dim=" << dim << " k=" << k << " q=" << q;
              ASSERT_EQ(batch_idx[q * k + j], brute_idx[j]) << "n=" << n << " dim=" << dim << " k=" << k;
              ASSERT_EQ(batch_d[q * k + j], brute_d[j]) << "n=" << n << " dim=" << dim << " k=" << k;
            }
          }
        }
      }
}

TEST(KDTreeEntryPoints, RefuseBadInput) {
  std::vector<float> rows(30, 0.0f);
  const mmrl::KDTree tree(rows.data(), 10, 3, 4);
  int64_t idx[11];
  float d[11];
  EXPECT_THROW(mmrl::kdtree_knn(tree, nullptr, 1, idx, d), std::invalid_argument);
  EXPECT_THROW(mmrl::kdtree_knn(tree, rows.data(), 0, idx, d), std::invalid_argument);
  EXPECT_THROW(mmrl::kdtree_knn(tree, rows.data(), 11, idx, d), std::invalid_argument);
  EXPECT_THROW(mmrl::kdtree_knn_batch(tree, rows.data(), -1, 1, idx, d), std::invalid_argument);
  EXPECT_THROW(mmrl::kdtree_knn_batch(tree, nullptr, 2, 1, idx, d), std::invalid_argument);
  mmrl::kdtree_knn_batch(tree, nullptr, 0, 1, nullptr, nullptr);  // nothing to do
  mmrl::ThreadPool pool(2);
  EXPECT_THROW(mmrl::kdtree_knn_batch(tree, rows.data(), 2, 0, idx, d, pool), std::invalid_argument);
  EXPECT_THROW(mmrl::kdtree_knn_batch(tree, rows.data(), 2, 11, idx, d, pool), std::invalid_argument);
  EXPECT_THROW(mmrl::kdtree_knn_batch(tree, rows.data(), -1, 1, idx, d, pool), std::invalid_argument);
  EXPECT_THROW(mmrl::kdtree_knn_batch(tree, rows.data(), 2, 1, nullptr, d, pool), std::invalid_argument);
  mmrl::kdtree_knn_batch(tree, nullptr, 0, 1, nullptr, nullptr, pool);
}

}  // namespace
