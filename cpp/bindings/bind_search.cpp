// Bindings for kdtree.hpp and search.hpp: convert, check, forward. The GIL is released
// while C++ searches; outputs are numpy arrays allocated here and filled in place.
#include <memory>

#include "bindings.hpp"
#include "py_matcher.hpp"
#include "mmrl/decision.hpp"
#include "mmrl/kdtree.hpp"
#include "mmrl/search.hpp"
#include "mmrl/threadpool.hpp"

namespace mmrl {

namespace {

// The tree borrows the rows: keep the numpy array alive with it.
struct PyKDTree {
  carray<float> points;
  KDTree tree;
  std::unique_ptr<ThreadPool> pool;  // query() answers its batch across these threads
};

carray<float> check_points(const py::handle& obj) {
  auto points = check_array<float>(obj, "points", {-1, -1});
  if (points.shape(1) < 1 || points.shape(1) > kMaxDim)
    throw py::value_error("points: expected 1 to " + std::to_string(kMaxDim) + " columns, got " +
                          std::to_string(points.shape(1)));
  check_finite(points.data(), points.size(), "points");
  return points;
}

carray<float> check_queries(const py::handle& obj, py::ssize_t dim) {
  auto queries = check_array<float>(obj, "queries", {-1, dim});
  check_finite(queries.data(), queries.size(), "queries");
  return queries;
}

// A (n,) uint8 or bool array, as bytes (numpy bools are one byte, 0 or 1).
py::array check_mask(const py::handle& obj, py::ssize_t n) {
  if (!py::isinstance<py::array>(obj))
    throw py::type_error("valid_mask: expected a numpy array, got " +
                         std::string(py::str(py::type::of(obj).attr("__name__"))));
  py::array arr = py::reinterpret_borrow<py::array>(obj);
  if (!has_dtype<uint8_t>(arr) && !has_dtype<bool>(arr))
    throw py::type_error("valid_mask: expected dtype uint8 or bool, got " + std::string(py::str(arr.dtype())));
  if (arr.ndim() != 1 || arr.shape(0) != n)
    throw py::value_error("valid_mask: expected shape (" + std::to_string(n) + ",), got ndim " +
                          std::to_string(arr.ndim()) + (arr.ndim() == 1 ? " size " + std::to_string(arr.shape(0)) : ""));
  if (!(arr.flags() & py::array::c_style))
    throw py::value_error("valid_mask: array must be C-contiguous (use np.ascontiguousarray)");
  return arr;
}

using MatchFn = void (Matcher::*)(const float*, int64_t, int64_t*, float*, ThreadPool&, const int64_t*,
                                  const int64_t*, const int64_t*) const;

py::tuple run_match(PyMatcher& self, const py::handle& queries_obj, const py::object& bounds_obj,
                    const py::object& exclude_obj, MatchFn fn) {
  auto queries = check_queries(queries_obj, self.matcher.dim());
  const py::ssize_t m = queries.shape(0);
  const int64_t* bounds = nullptr;
  carray<int64_t> bound_arr;
  if (!bounds_obj.is_none()) {
    bound_arr = check_array<int64_t>(bounds_obj, "bound_indices", {m});
    bounds = bound_arr.data();
    for (py::ssize_t i = 0; i < m; ++i)
      if (bounds[i] < -1 || bounds[i] >= self.matcher.num_rows())
        throw py::value_error("bound_indices: entry " + std::to_string(i) + " = " + std::to_string(bounds[i]) +
                              " is outside [-1, " + std::to_string(self.matcher.num_rows()) + ")");
  }
  // Optional per-query excluded windows [lo, hi) as an (M, 2) int64 array.
  const int64_t* lo = nullptr;
  const int64_t* hi = nullptr;
  std::vector<int64_t> lo_hi;
  if (!exclude_obj.is_none()) {
    auto ex = check_array<int64_t>(exclude_obj, "exclude", {m, 2});
    lo_hi.resize(static_cast<size_t>(m) * 2);
    for (py::ssize_t i = 0; i < m; ++i) {
      lo_hi[i] = ex.at(i, 0);
      lo_hi[m + i] = ex.at(i, 1);
    }
    lo = lo_hi.data();
    hi = lo_hi.data() + m;
  }
  py::array_t<int64_t> indices(m);
  py::array_t<float> costs(m);
  {
    py::gil_scoped_release release;
    (self.matcher.*fn)(queries.data(), m, indices.mutable_data(), costs.mutable_data(), *self.pool, lo, hi, bounds);
  }
  return py::make_tuple(indices, costs);
}

}  // namespace

// Matcher.escape_table: the obstacles search's escapes (decision.hpp), for the export.
void def_escape_table(py::class_<PyMatcher>& c) {
  c.def(
      "escape_table",
      [](const PyMatcher& self, const Database& db, int escapes, int k) {
        if (self.matcher.num_rows() != db.num_frames)
          throw py::value_error("escape_table: the matcher is not over this database");
        std::shared_ptr<const EscapeTable> table;
        {
          py::gil_scoped_release release;
          table = EscapeTable::shared(db, self.matcher, escapes, k);
        }
        const auto rows = static_cast<py::ssize_t>(db.num_frames), cols = static_cast<py::ssize_t>(table->row_count());
        py::array_t<int32_t> out({rows, cols});
        std::copy(table->all_rows().begin(), table->all_rows().end(), out.mutable_data());
        return out;
      },
      py::arg("db"), py::arg("escapes"), py::arg("k"),
      "The escapes' table over db (decision.hpp's EscapeTable, shared with every env over this matcher): per "
      "frame, the k nearest frames of each of the first `escapes` escape queries (-1 where fewer exist); "
      "num_frames x escapes * k int32. ValueError on counts out of range.");
}

void bind_search(py::module_& m) {
  py::class_<PyKDTree>(m, "KDTree",
                       "Exact k-NN KD-tree over float32 rows (squared L2). Borrows `points` (kept alive) and "
                       "holds a permuted, blocked copy of the rows in its leaves. query() runs across num_threads threads "
                       "(0 = all cores).")
      .def(py::init([](const py::handle& points_obj, int leaf_size, int num_threads) {
             auto points = check_points(points_obj);
             if (leaf_size < 1) throw py::value_error("leaf_size: must be >= 1, got " + std::to_string(leaf_size));
             if (num_threads < 0) throw py::value_error("num_threads: must be >= 0 (0 = all cores)");
             KDTree tree(points.data(), points.shape(0), static_cast<int>(points.shape(1)), leaf_size);
             return new PyKDTree{points, std::move(tree), std::make_unique<ThreadPool>(num_threads)};
           }),
           py::arg("points"), py::arg("leaf_size") = 16, py::arg("num_threads") = 0)
      .def(
          "query",
          [](const PyKDTree& self, const py::handle& queries_obj, int k) {
            auto queries = check_queries(queries_obj, self.tree.dim());
            const int64_t n = self.tree.indexed_size();
            if (k < 1 || k > std::max<int64_t>(1, n))
              throw py::value_error("k: must be in [1, " + std::to_string(std::max<int64_t>(1, n)) + "], got " +
                                    std::to_string(k));
            const py::ssize_t mq = queries.shape(0);
            py::array_t<int64_t> indices({mq, static_cast<py::ssize_t>(k)});
            py::array_t<float> dists({mq, static_cast<py::ssize_t>(k)});
            {
              py::gil_scoped_release release;
              kdtree_knn_batch(self.tree, queries.data(), mq, k, indices.mutable_data(), dists.mutable_data(), *self.pool);
            }
            return py::make_tuple(indices, dists);
          },
          py::arg("queries"), py::arg("k") = 1,
          "(M, D) float32 queries -> (indices int64 (M, k), squared distances float32 (M, k)), nearest first; "
          "ties go to the lower index.")
      .def_property_readonly("size", [](const PyKDTree& self) { return self.tree.size(); })
      .def_property_readonly("dim", [](const PyKDTree& self) { return self.tree.dim(); })
      .def_property_readonly("leaf_size", [](const PyKDTree& self) { return self.tree.leaf_size(); })
      .def_property_readonly("depth", [](const PyKDTree& self) { return self.tree.depth(); })
      .def_property_readonly("num_threads", [](const PyKDTree& self) { return self.pool->num_threads(); });

  py::class_<PyMatcher> matcher_class(m, "Matcher",
                        "Motion-matching search over normalized feature rows: nearest valid row, optionally "
                        "bounded by the current frame's continuation. Borrows `points` and `valid_mask`.");
  matcher_class
      .def(py::init([](const py::handle& points_obj, const py::handle& mask_obj, int num_threads, int leaf_size) {
             auto points = check_points(points_obj);
             auto valid = check_mask(mask_obj, points.shape(0));
             if (num_threads < 0) throw py::value_error("num_threads: must be >= 0 (0 = all cores)");
             if (leaf_size < 1) throw py::value_error("leaf_size: must be >= 1, got " + std::to_string(leaf_size));
             MatcherOptions opts;
             opts.leaf_size = leaf_size;
             const auto* mask = static_cast<const uint8_t*>(valid.data());
             Matcher matcher(points.data(), points.shape(0), static_cast<int>(points.shape(1)), mask, opts);
             return new PyMatcher{points, valid, std::move(matcher), std::make_unique<ThreadPool>(num_threads)};
           }),
           py::arg("points"), py::arg("valid_mask"), py::arg("num_threads") = 0, py::arg("leaf_size") = 16)
      .def(
          "match",
          [](PyMatcher& self, const py::handle& q, const py::object& b, const py::object& ex) {
            return run_match(self, q, b, ex, &Matcher::match_batch);
          },
          py::arg("queries"), py::arg("bound_indices") = py::none(), py::arg("exclude") = py::none(),
          "(M, D) float32 normalized queries [, (M,) int64 bound indices, -1 = none] [, (M, 2) int64 excluded "
          "row windows [lo, hi)] -> (indices int64 (M,), squared costs float32 (M,)). Index -1 when no valid row "
          "exists and there is no bound.")
      .def(
          "brute_force",
          [](PyMatcher& self, const py::handle& q, const py::object& b, const py::object& ex) {
            return run_match(self, q, b, ex, &Matcher::brute_force_batch);
          },
          py::arg("queries"), py::arg("bound_indices") = py::none(), py::arg("exclude") = py::none(),
          "The same contract as match(), answered by a brute-force scan (the reference).")
      .def_property_readonly("num_rows", [](const PyMatcher& self) { return self.matcher.num_rows(); })
      .def_property_readonly("num_valid", [](const PyMatcher& self) { return self.matcher.num_valid(); })
      .def_property_readonly("dim", [](const PyMatcher& self) { return self.matcher.dim(); })
      .def_property_readonly("num_threads", [](const PyMatcher& self) { return self.pool->num_threads(); });
  def_escape_table(matcher_class);
}

}  // namespace mmrl
