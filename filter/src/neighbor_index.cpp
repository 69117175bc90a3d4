#include "neighbor_index.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <nanoflann.hpp>
#include <utility>

#include "fill_later.h"
#include "huge_pages.h"
#include "parallel.h"
#include "radix_sort.h"

namespace scanclean {
namespace {

// Fibonacci hashing: the top `bits` of key x 2^64 / phi, which every bit of the key moves
// (the low bits of the product ignore the key's high bits, its z).
std::uint64_t hash_of(std::uint64_t key, int bits) {
  return (key * 0x9E3779B97F4A7C15ULL) >> (64 - bits);
}

constexpr std::uint64_t kEmpty = ~0ULL;

// Spreads the low 21 bits of v so that there are two zero bits between consecutive bits.
std::uint64_t spread_bits(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

}  // namespace

std::uint64_t morton(std::int32_t x, std::int32_t y, std::int32_t z) {
  return spread_bits(static_cast<std::uint64_t>(x)) |
         (spread_bits(static_cast<std::uint64_t>(y)) << 1) |
         (spread_bits(static_cast<std::uint64_t>(z)) << 2);
}

struct NeighborIndex::Tree {
  struct Adaptor {
    const std::vector<Eigen::Vector3f>* pts;
    std::size_t kdtree_get_point_count() const { return pts->size(); }
    float kdtree_get_pt(std::size_t i, std::size_t d) const { return (*pts)[i][d]; }
    template <class B>
    bool kdtree_get_bbox(B&) const {
      return false;
    }
  };
  using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Adaptor>,
                                                     Adaptor, 3, std::uint32_t>;
  explicit Tree(const std::vector<Eigen::Vector3f>* pts)
      : adaptor{pts}, tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    tree.buildIndex();
  }
  Adaptor adaptor;
  KdTree tree;
};

NeighborIndex::NeighborIndex(std::vector<Eigen::Vector3f>&& points, double cell) {
  build(points, &points, cell);
}

NeighborIndex::NeighborIndex(const std::vector<Eigen::Vector3f>& points, double cell) {
  build(points, nullptr, cell);
}

void NeighborIndex::build(const std::vector<Eigen::Vector3f>& points,
                          std::vector<Eigen::Vector3f>* owned, double cell) {
  assert(cell >= 0);
  const std::size_t n = points.size();
  cell_ = cell;
  if (n == 0) {
    cell_begin_.push_back(0);
    return;
  }
  if (cell <= 0) {  // tree only
    grid_ = false;
    if (owned)
      pts_ = std::move(*owned);
    else
      pts_ = points;
    ids_.resize(n);
    for (std::size_t i = 0; i < n; ++i) ids_[i] = static_cast<std::uint32_t>(i);
    inv_ = ids_;
    return;
  }
  const Eigen::AlignedBox3f box = detail::bounding_box_of(points);
  const Eigen::Vector3f lo = box.min(), hi = box.max();
  const double max_extent = (hi - lo).cast<double>().maxCoeff();
  constexpr double kMaxCells = (1 << 21) - 2;
  if (max_extent / cell > kMaxCells) cell = max_extent / kMaxCells * (1 + 1e-6);
  // Widen the box a little so that rounding never puts a point outside.
  lo_ = lo - Eigen::Vector3f::Constant(static_cast<float>(cell) * 0.5f);
  cell_ = cell;
  inv_cell_ = static_cast<float>(1.0 / cell);
  for (int a = 0; a < 3; ++a)
    dims_[a] = std::min<std::int32_t>(
        static_cast<std::int32_t>(std::floor((hi[a] - lo_[a]) * inv_cell_)) + 2, (1 << 21) - 1);

  auto coords = [&](const Eigen::Vector3f& p, int a) {
    const float c = std::floor((p[a] - lo_[a]) * inv_cell_);
    return static_cast<std::int32_t>(std::clamp(c, 0.0f, static_cast<float>(dims_[a] - 1)));
  };
  struct Entry {  // 16 bytes; the Morton code identifies the cell
    std::uint64_t morton;
    std::uint64_t id;
  };
  detail::FillLaterVector<Entry> entries(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) {
                        const auto& p = points[i];
                        const std::int32_t x = coords(p, 0), y = coords(p, 1), z = coords(p, 2);
                        entries[i] = {morton(x, y, z), static_cast<std::uint64_t>(i)};
                      }
                    });
  // By Morton code, then id (the entries start in id order, and the sort is stable).
  {
    detail::FillLaterVector<Entry> scratch;
    detail::stable_radix_sort(
        entries, [](const Entry& e) { return e.morton; }, scratch);
  }
  detail::resize_huge(pts_, n);
  detail::resize_huge(ids_, n);
  detail::resize_huge(inv_, n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t s = r.begin(); s < r.end(); ++s) {
                        ids_[s] = static_cast<std::uint32_t>(entries[s].id);
                        inv_[entries[s].id] = static_cast<std::uint32_t>(s);
                        pts_[s] = points[entries[s].id];
                      }
                    });
  if (owned) std::vector<Eigen::Vector3f>().swap(*owned);
  cell_begin_ = detail::indices_where(
      n, [&](std::size_t s) { return s == 0 || entries[s].morton != entries[s - 1].morton; });
  std::vector<std::uint64_t> keys(cell_begin_.size());
  detail::parallel_each(keys.size(), [&](std::size_t c) {
    const auto& p = pts_[cell_begin_[c]];
    keys[c] = detail::cell_key(coords(p, 0), coords(p, 1), coords(p, 2));
  });
  detail::FillLaterVector<Entry>().swap(entries);
  cell_begin_.push_back(static_cast<std::uint32_t>(n));
  std::size_t cap = 16;
  while (cap < 2 * keys.size()) cap *= 2;
  hash_mask_ = cap - 1;
  hash_bits_ = std::countr_zero(cap);
  detail::assign_huge(hash_keys_, cap, kEmpty);
  detail::assign_huge<std::uint32_t>(hash_cells_, cap, 0);
  for (std::size_t c = 0; c < keys.size(); ++c) {
    std::uint64_t h = hash_of(keys[c], hash_bits_);
    while (true) {
      const std::uint64_t slot = h & hash_mask_;
      if (hash_keys_[slot] == kEmpty) {
        hash_keys_[slot] = keys[c];
        hash_cells_[slot] = static_cast<std::uint32_t>(c);
        break;
      }
      ++h;
    }
  }
  // Occupied neighbours of every cell (27-neighbourhood), in a fixed order.
  const std::size_t nc = keys.size();
  std::vector<std::array<std::uint32_t, 27>> adj(nc);
  std::vector<std::uint8_t> adj_n(nc, 0);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, nc, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t c = r.begin(); c < r.end(); ++c) {
          const std::uint64_t k = keys[c];
          const auto x = static_cast<std::int32_t>(k & 0x1fffff);
          const auto y = static_cast<std::int32_t>((k >> 21) & 0x1fffff);
          const auto z = static_cast<std::int32_t>((k >> 42) & 0x1fffff);
          std::uint8_t m = 0;
          for (std::int32_t dz = -1; dz <= 1; ++dz)
            for (std::int32_t dy = -1; dy <= 1; ++dy)
              for (std::int32_t dx = -1; dx <= 1; ++dx) {
                const std::int32_t a = x + dx, b = y + dy, e = z + dz;
                if (a < 0 || b < 0 || e < 0 || a >= dims_[0] || b >= dims_[1] || e >= dims_[2])
                  continue;
                const std::int64_t cc = find_cell(detail::cell_key(a, b, e));
                if (cc >= 0) adj[c][m++] = static_cast<std::uint32_t>(cc);
              }
          std::sort(adj[c].begin(), adj[c].begin() + m);
          adj_n[c] = m;
        }
      });
  adj_begin_.resize(nc + 1);
  adj_begin_[0] = 0;
  for (std::size_t c = 0; c < nc; ++c) adj_begin_[c + 1] = adj_begin_[c] + adj_n[c];
  detail::resize_huge(adj_, adj_begin_[nc]);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, nc, 1024), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t c = r.begin(); c < r.end(); ++c)
          std::copy(adj[c].begin(), adj[c].begin() + adj_n[c], adj_.begin() + adj_begin_[c]);
      });
  // The fast path needs |cell(p) - cell(q)| <= 1 for |p - q| < r, under float rounding of the
  // cell coordinates (about dims x 2^-23 cells): keep r below the cell by that margin.
  const double max_dim = std::max({dims_[0], dims_[1], dims_[2]});
  cell_f_ = static_cast<float>(cell_ * (1.0 - 1e-5 - 4.0 * max_dim / 8388608.0));
}

NeighborIndex::~NeighborIndex() = default;

std::int64_t NeighborIndex::find_cell(std::uint64_t key) const {
  std::uint64_t h = hash_of(key, hash_bits_);
  while (true) {
    const std::uint64_t slot = h & hash_mask_;
    const std::uint64_t k = hash_keys_[slot];
    if (k == key) return hash_cells_[slot];
    if (k == kEmpty) return -1;
    ++h;
  }
}

std::vector<std::uint32_t> NeighborIndex::adjacent_counts() const {
  const std::size_t cells = cell_count();
  std::vector<std::uint32_t> out(cells, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells, 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t c = r.begin(); c < r.end(); ++c) {
                        std::uint32_t b = 0;
                        for_each_adjacent_run(
                            c, [&](std::uint32_t s, std::uint32_t e) { b += e - s; });
                        out[c] = b;
                      }
                    });
  return out;
}

std::uint32_t NeighborIndex::value_at_point_rank(const std::vector<std::uint32_t>& per_cell,
                                                 std::size_t rank) const {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> v(per_cell.size());  // value, points
  for (std::size_t c = 0; c < v.size(); ++c)
    v[c] = {per_cell[c], cell_begin_[c + 1] - cell_begin_[c]};
  std::sort(v.begin(), v.end());
  std::size_t seen = 0;
  for (const auto& [value, points] : v) {
    seen += points;
    if (seen > rank) return value;
  }
  return v.empty() ? 0 : v.back().first;
}

const NeighborIndex::Tree& NeighborIndex::tree() const {
  std::call_once(tree_once_, [this] { tree_ = std::make_unique<Tree>(&pts_); });
  return *tree_;
}

void NeighborIndex::tree_within(const Eigen::Vector3f& q, float r,
                                std::vector<std::pair<std::uint32_t, float>>& out) const {
  out.clear();
  nanoflann::SearchParams params(32, 0, false);
  tree().tree.radiusSearch(q.data(), r * r, out, params);
  // nanoflann's radius test is <=; keep the strict one, report original indices, fixed order.
  std::size_t k = 0;
  for (const auto& [s, d2] : out)
    if (d2 < r * r) out[k++] = {s, d2};
  out.resize(k);
  std::sort(out.begin(), out.end());
  for (auto& e : out) e.first = ids_[e.first];
}

void NeighborIndex::knn(const Eigen::Vector3f& q, std::size_t k,
                        std::vector<std::pair<float, std::uint32_t>>& out) const {
  k = std::min(k, pts_.size());
  thread_local std::vector<std::uint32_t> idx;
  thread_local std::vector<float> d2;
  idx.resize(k);
  d2.resize(k);
  const std::size_t found = tree().tree.knnSearch(q.data(), k, idx.data(), d2.data());
  out.resize(found);
  for (std::size_t i = 0; i < found; ++i) out[i] = {d2[i], ids_[idx[i]]};
  std::sort(out.begin(), out.end());
}

void NeighborIndex::build_tree() const {
  tree();
}

double rough_kth_distance(const std::vector<Eigen::Vector3f>& p, std::size_t kk,
                          std::size_t samples) {
  const std::size_t n = p.size(), m = std::min(n, samples);
  if (m == 0) return 0;
  const std::size_t step = std::clamp<std::size_t>(n / (8 * kk), 1, 16);
  const std::size_t ks = std::max<std::size_t>(2, (kk + step / 2) / step);
  // A large subsample in two halves (alternate points), a k-d tree each, built side by side (a
  // tree is built by one thread): the ks nearest of the subsample are among the ks nearest of
  // each half, so the ks-th distance is the one a single tree gives.
  const std::size_t parts = n / step >= 8192 ? 2 : 1;
  std::vector<Eigen::Vector3f> half[2];
  for (std::size_t t = 0; t < parts; ++t) half[t].reserve(n / (parts * step) + 1);
  for (std::size_t i = 0, t = 0; i < n; i += step, t = (t + 1) % parts) half[t].push_back(p[i]);
  std::unique_ptr<NeighborIndex> tree[2];
  auto build = [&](std::size_t t) {
    tree[t] = std::make_unique<NeighborIndex>(std::move(half[t]), 0.0);  // k-d tree only
    tree[t]->build_tree();
  };
  if (parts == 2)
    tbb::parallel_invoke([&] { build(0); }, [&] { build(1); });
  else
    build(0);
  std::vector<double> est(m, 0.0);
  detail::parallel_each(m, [&](std::size_t k) {
    thread_local std::vector<std::pair<float, std::uint32_t>> nn[2];
    for (std::size_t t = 0; t < parts; ++t) tree[t]->knn(p[k * n / m], ks, nn[t]);
    if (parts == 1) nn[1].clear();
    // The take-th smallest of the two sorted lists.
    const std::size_t take = std::min(ks, nn[0].size() + nn[1].size());
    if (take == 0) return;
    std::size_t a = 0, b = 0;
    float d2 = 0;
    for (std::size_t c = 0; c < take; ++c) {
      const bool from_a =
          b == nn[1].size() || (a < nn[0].size() && nn[0][a].first <= nn[1][b].first);
      d2 = from_a ? nn[0][a++].first : nn[1][b++].first;
    }
    est[k] = std::sqrt(static_cast<double>(d2));
  });
  return detail::median_of(est);
}

}  // namespace scanclean
