// KDTree == brute force, exactly (same indices, bit-identical squared distances).
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "mmrl/kdtree.hpp"
#include "mmrl/search.hpp"

namespace {

std::vector<float> random_points(int64_t n, int dim, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<float> p(static_cast<size_t>(n * dim));
  for (auto& v : p) v = g(rng);
  return p;
}

// Compares the tree against brute force on `num_queries` queries: half near data rows,
// half random.
void expect_same_as_brute_force(const std::vector<float>& pts, int64_t n, int dim, int k, int leaf,
                                const mmrl::SearchFilter& filter, int num_queries, uint32_t seed,
                                const uint8_t* build_mask = nullptr) {
  mmrl::KDTree tree(pts.data(), n, dim, leaf, build_mask);
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<float> q(dim);
  std::vector<int64_t> ti(k), bi(k);
  std::vector<float> td(k), bd(k);
  std::vector<uint8_t> allowed;
  mmrl::SearchFilter brute_filter = filter;
  if (build_mask) {  // the brute force sees the build mask and the query mask combined
    allowed.assign(static_cast<size_t>(n), 0);
    for (int64_t i = 0; i < n; ++i) allowed[i] = build_mask[i] && (!filter.allowed || filter.allowed[i]);
    brute_filter.allowed = allowed.data();
  }
  for (int t = 0; t < num_queries; ++t) {
    if (n > 0 && t % 2 == 0) {
      const int64_t row = std::uniform_int_distribution<int64_t>(0, n - 1)(rng);
      for (int d = 0; d < dim; ++d) q[d] = pts[row * dim + d] + 0.05f * g(rng);
    } else {
      for (int d = 0; d < dim; ++d) q[d] = 2.0f * g(rng);
    }
    const int tf = tree.knn(q.data(), k, ti.data(), td.data(), filter);
    const int bf = mmrl::brute_force_knn(pts.data(), n, dim, q.data(), k, bi.data(), bd.data(), brute_filter);
    ASSERT_EQ(tf, bf) << "n=" << n << " dim=" << dim << " k=" << k << " leaf=" << leaf;
    for (int j = 0; j < k; ++j) {
      ASSERT_EQ(ti[j], bi[j]) << "n=" << n << " dim=" << dim << " k=" << k << " leaf=" << leaf << " slot " << j;
      ASSERT_EQ(td[j], bd[j]) << "n=" << n << " dim=" << dim << " k=" << k << " leaf=" << leaf << " slot " << j;
    }
  }
}

TEST(KDTree, EqualsBruteForceAcrossSizesDimsKAndLeafSizes) {
  for (int64_t n : {1, 2, 17, 1000, 20000})
    for (int dim : {1, 2, 5, 27})
      for (int leaf : {1, 4, 16, 64})
        for (int k : {1, 3, 10}) {
          if (k > n) continue;
          const auto pts = random_points(n, dim, static_cast<uint32_t>(n * 131 + dim));
          expect_same_as_brute_force(pts, n, dim, k, leaf, {}, n >= 20000 ? 20 : 40, 7);
        }
}

TEST(KDTree, EmptyTreeFindsNothing) {
  mmrl::KDTree tree(nullptr, 0, 3, 16);
  const float q[3] = {0, 0, 0};
  int64_t idx[2] = {7, 7};
  float d[2] = {0, 0};
  EXPECT_EQ(tree.knn(q, 1, idx, d), 0);
  EXPECT_EQ(idx[0], -1);
  EXPECT_TRUE(std::isinf(d[0]));
  EXPECT_THROW(tree.knn(q, 2, idx, d), std::invalid_argument);
}

TEST(KDTree, OneRowTree) {
  const float p[2] = {1.0f, 2.0f};
  mmrl::KDTree tree(p, 1, 2, 16);
  const float q[2] = {0.0f, 0.0f};
  int64_t idx = -5;
  float d = 0;
  EXPECT_EQ(tree.knn(q, 1, &idx, &d), 1);
  EXPECT_EQ(idx, 0);
  EXPECT_EQ(d, 5.0f);
}

TEST(KDTree, RandomMasksAndExcludeWindows) {
  const int64_t n = 5000;
  for (int dim : {2, 27}) {
    const auto pts = random_points(n, dim, 11u + dim);
    std::mt19937 rng(3);
    std::vector<uint8_t> mask(n);
    for (auto& m : mask) m = (rng() % 3) != 0;
    mmrl::SearchFilter f;
    f.allowed = mask.data();
    for (int leaf : {1, 16, 64})
      for (int k : {1, 3, 10}) {
        expect_same_as_brute_force(pts, n, dim, k, leaf, f, 30, 5);
        mmrl::SearchFilter w = f;
        w.exclude_lo = 1000;
        w.exclude_hi = 3500;
        expect_same_as_brute_force(pts, n, dim, k, leaf, w, 30, 6);
        w.allowed = nullptr;
        expect_same_as_brute_force(pts, n, dim, k, leaf, w, 30, 8);
        // A build mask leaves rows out of the tree altogether.
        expect_same_as_brute_force(pts, n, dim, k, leaf, {}, 30, 9, mask.data());
      }
  }
}

TEST(KDTree, MaskExcludingEverythingReturnsMinusOne) {
  const int64_t n = 300;
  const auto pts = random_points(n, 5, 1);
  std::vector<uint8_t> none(n, 0);
  mmrl::KDTree tree(pts.data(), n, 5, 8);
  mmrl::SearchFilter f;
  f.allowed = none.data();
  int64_t idx[3];
  float d[3];
  EXPECT_EQ(tree.knn(pts.data(), 3, idx, d, f), 0);
  for (int j = 0; j < 3; ++j) {
    EXPECT_EQ(idx[j], -1);
    EXPECT_TRUE(std::isinf(d[j]));
  }
  mmrl::SearchFilter all_window;
  all_window.exclude_lo = 0;
  all_window.exclude_hi = n;
  EXPECT_EQ(tree.knn(pts.data(), 1, idx, d, all_window), 0);
  EXPECT_EQ(idx[0], -1);
  // Build mask excluding everything: an empty tree.
  mmrl::KDTree empty(pts.data(), n, 5, 8, none.data());
  EXPECT_EQ(empty.indexed_size(), 0);
  EXPECT_EQ(empty.knn(pts.data(), 1, idx, d), 0);
  EXPECT_EQ(idx[0], -1);
}

TEST(KDTree, DuplicatePointsTieToLowestIndex) {
  // Many exact duplicates (a few distinct rows repeated): ties everywhere.
  const int64_t n = 2000;
  const int dim = 4;
  const auto base = random_points(7, dim, 2);
  std::vector<float> pts(n * dim);
  std::mt19937 rng(4);
  for (int64_t i = 0; i < n; ++i) {
    const int r = static_cast<int>(rng() % 7);
    for (int d = 0; d < dim; ++d) pts[i * dim + d] = base[r * dim + d];
  }
  for (int leaf : {1, 4, 16, 64})
    for (int k : {1, 3, 10}) expect_same_as_brute_force(pts, n, dim, k, leaf, {}, 40, 12);
  // All rows identical: the first k indices, in order.
  std::vector<float> same(500 * 3, 0.25f);
  mmrl::KDTree tree(same.data(), 500, 3, 4);
  int64_t idx[10];
  float d[10];
  const float q[3] = {0, 0, 0};
  tree.knn(q, 10, idx, d);
  for (int j = 0; j < 10; ++j) EXPECT_EQ(idx[j], j);
}

TEST(KDTree, RefusesBadInput) {
  const auto pts = random_points(10, 3, 1);
  EXPECT_THROW(mmrl::KDTree(nullptr, 10, 3, 16), std::invalid_argument);
  EXPECT_THROW(mmrl::KDTree(pts.data(), 10, 0, 16), std::invalid_argument);
  EXPECT_THROW(mmrl::KDTree(pts.data(), 10, -1, 16), std::invalid_argument);
  EXPECT_THROW(mmrl::KDTree(pts.data(), -1, 3, 16), std::invalid_argument);
  EXPECT_THROW(mmrl::KDTree(pts.data(), 10, 3, 0), std::invalid_argument);
  EXPECT_THROW(mmrl::KDTree(pts.data(), 10, mmrl::KDTree::kMaxDim + 1, 16), std::invalid_argument);
  mmrl::KDTree tree(pts.data(), 10, 3, 4);
  int64_t idx[11];
  float d[11];
  EXPECT_THROW(tree.knn(nullptr, 1, idx, d), std::invalid_argument);
  EXPECT_THROW(tree.knn(pts.data(), 1, nullptr, d), std::invalid_argument);
  EXPECT_THROW(tree.knn(pts.data(), 1, idx, nullptr), std::invalid_argument);
  EXPECT_THROW(tree.knn(pts.data(), 0, idx, d), std::invalid_argument);
  EXPECT_THROW(tree.knn(pts.data(), 11, idx, d), std::invalid_argument);
  EXPECT_THROW(tree.nearest_with_bound(pts.data(), 10, d), std::out_of_range);
  EXPECT_THROW(mmrl::brute_force_knn(pts.data(), 10, 3, pts.data(), 11, idx, d), std::invalid_argument);
  EXPECT_THROW(mmrl::brute_force_knn(pts.data(), 10, 3, pts.data(), 0, idx, d), std::invalid_argument);
  EXPECT_THROW(mmrl::brute_force_knn(nullptr, 10, 3, pts.data(), 1, idx, d), std::invalid_argument);
  EXPECT_THROW(mmrl::brute_force_knn(pts.data(), 10, 0, pts.data(), 1, idx, d), std::invalid_argument);
}

}  // namespace
