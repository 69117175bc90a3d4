#pragma once
//! \file neighbor_index.h
//! Exact fixed-radius and k-nearest-neighbour queries on a 3D point set, used by the robust
//! filter. Points are held in float (callers pass coordinates relative to a local origin, so
//! that float keeps sub-micrometre resolution near the data). A uniform hash grid answers
//! queries whose radius spans few cells; larger radii and k-nearest queries go to a k-d tree
//! (nanoflann, hidden behind a PImpl) that is built on first use.

#include <Eigen/Core>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

namespace scanclean {

class NeighborIndex {
 public:
  //! Builds the index. `points` in metres (any local frame); `cell` > 0 is the grid cell edge in
  //! metres (choose about the typical query radius). The cell is enlarged if the extent would
  //! need more than 2^21 cells per axis. Non-finite coordinates are not allowed (assert).
  //! Construction runs in the caller's TBB arena; the result does not depend on the thread count.
  //! This overload takes the array over and frees it during the build (lower peak memory).
  NeighborIndex(std::vector<Eigen::Vector3f>&& points, double cell);
  //! The same index over an array the caller keeps (read, not copied).
  NeighborIndex(const std::vector<Eigen::Vector3f>& points, double cell);
  ~NeighborIndex();
  NeighborIndex(const NeighborIndex&) = delete;
  NeighborIndex& operator=(const NeighborIndex&) = delete;

  std::size_t size() const { return pts_.size(); }
  double cell() const { return cell_; }
  //! Point indices (into the constructor's array) in grid order: Morton order of the cells,
  //! ascending index inside a cell. A cache-friendly processing order.
  const std::vector<std::uint32_t>& order() const { return ids_; }
  //! The point with the given original index.
  const Eigen::Vector3f& point(std::uint32_t i) const { return pts_[inv_[i]]; }

  //! Calls f(index, squared_distance) for every point p with |p - q| < r (strict). The visiting
  //! order is deterministic (depends on q and r only). Thread-safe (const).
  template <class F>
  void for_each_within(const Eigen::Vector3f& q, float r, F&& f) const {
    visit<false>(q, r, f);
  }
  //! As for_each_within, but passes the grid slot (position in order()) instead of the index.
  template <class F>
  void for_each_slot_within(const Eigen::Vector3f& q, float r, F&& f) const {
    visit<true>(q, r, f);
  }
  //! The occupied cell whose adjacent runs (for_each_adjacent_run) for_each_cell_run(q, r, f)
  //! passes to f, in that order, when it takes its fast path; -1 when it does not.
  std::int64_t adjacent_cell(const Eigen::Vector3f& q, float r) const;
  //! The octant of q's grid cell that holds q (0-7: bit a set for the upper half along axis a),
  //! and its box, grown by 1e-4 cells on every side. The box is the same for every q of the
  //! octant (a function of the octant only); rounding may leave a q at an octant's edge just
  //! outside it, which callers check. Only meaningful for a q inside the grid (adjacent_cell()).
  int cell_octant(const Eigen::Vector3f& q, Eigen::Vector3f& box_lo, Eigen::Vector3f& box_hi) const;
  //! Calls f(begin_slot, end_slot) for every occupied grid cell that may hold points within r
  //! of q (a superset of the ball; callers filter by distance). Returns false, calling nothing,
  //! when r is too large for the grid (use for_each_slot_within then).
  template <class F>
  bool for_each_cell_run(const Eigen::Vector3f& q, float r, F&& f) const;
  //! The point in grid slot s (that is, point(order()[s])).
  const Eigen::Vector3f& slot_point(std::size_t s) const { return pts_[s]; }
  //! Grid slot of original index i.
  std::uint32_t slot_of(std::uint32_t i) const { return inv_[i]; }

  //! Occupied grid cells (0 without a grid). Cell c holds the slots [cell_begin(c),
  //! cell_begin(c + 1)); cells are in grid order.
  std::size_t cell_count() const { return grid_ ? cell_begin_.size() - 1 : 0; }
  std::uint32_t cell_begin(std::size_t c) const { return cell_begin_[c]; }
  //! Calls f(begin_slot, end_slot) for the occupied cells among the 27 around occupied cell c
  //! (c included): they hold every point within max_adjacent_radius() of a point of c.
  template <class F>
  void for_each_adjacent_run(std::size_t c, F&& f) const {
    for (std::uint32_t k = adj_begin_[c], ke = adj_begin_[c + 1]; k < ke; ++k)
      f(cell_begin_[adj_[k]], cell_begin_[adj_[k] + 1]);
  }
  float max_adjacent_radius() const { return cell_f_; }
  //! Per occupied cell, the points in its 27 adjacent cells (for_each_adjacent_run): an upper
  //! bound of the points within max_adjacent_radius() of any point of the cell. Parallel.
  std::vector<std::uint32_t> adjacent_counts() const;
  //! With every point taking its cell's value per_cell[c]: the value at 0-based rank `rank`
  //! (< size()) of those values in ascending order, e.g. the median over the points of
  //! adjacent_counts(), without an array per point.
  std::uint32_t value_at_point_rank(const std::vector<std::uint32_t>& per_cell,
                                    std::size_t rank) const;

  //! The k nearest points to q (including a point equal to q), as (squared distance, index),
  //! sorted by distance then index. Fewer if the set has fewer points. Thread-safe (const).
  void knn(const Eigen::Vector3f& q, std::size_t k,
           std::vector<std::pair<float, std::uint32_t>>& out) const;
  //! Builds the k-d tree behind knn() and the searches past the grid now, in the calling thread
  //! (else the first query that needs it builds it while the others wait).
  void build_tree() const;

 private:
  template <bool kSlots, class F>
  void visit(const Eigen::Vector3f& q, float r, F& f) const;
  // Distance test over slots [b, e), branch-free selection, then f for the hits in slot order.
  template <bool kSlots, class F>
  void scan(std::uint32_t b, std::uint32_t e, const Eigen::Vector3f& q, float r2, F& f) const {
    constexpr std::uint32_t kChunk = 64;
    std::uint32_t hit[kChunk];
    float hd[kChunk];
    const float qx = q.x(), qy = q.y(), qz = q.z();
    for (std::uint32_t s0 = b; s0 < e; s0 += kChunk) {
      const std::uint32_t s1 = std::min(e, s0 + kChunk);
      std::uint32_t n = 0;
      for (std::uint32_t s = s0; s < s1; ++s) {
        const float* p = pts_[s].data();
        const float dx = p[0] - qx, dy = p[1] - qy, dz = p[2] - qz;
        const float d2 = dx * dx + dy * dy + dz * dz;
        hit[n] = s;
        hd[n] = d2;
        n += d2 < r2 ? 1u : 0u;
      }
      for (std::uint32_t k = 0; k < n; ++k) f(kSlots ? hit[k] : ids_[hit[k]], hd[k]);
    }
  }
  // Cells per axis scanned by the grid path; past it, the k-d tree. With 4, the two points of the
  // 2.1M-point sphere of the speed suite (k = 250) whose gathers spanned 5 kernel cells built a
  // tree over 1.05M kernels for them (0.21 s on one core); 216 hash lookups cost microseconds.
  static constexpr int kMaxGridSpan = 6;
  void tree_within(const Eigen::Vector3f& q, float r,
                   std::vector<std::pair<std::uint32_t, float>>& out) const;
  std::int64_t find_cell(std::uint64_t key) const;  // cell number or -1

  // The constructors' body; `owned` (the array itself, or null) is freed once copied.
  void build(const std::vector<Eigen::Vector3f>& points, std::vector<Eigen::Vector3f>* owned,
             double cell);

  std::vector<Eigen::Vector3f> pts_;       // sorted in grid order
  std::vector<std::uint32_t> ids_;         // original index of pts_[s]
  std::vector<std::uint32_t> inv_;         // sorted slot of original index i
  std::vector<std::uint32_t> cell_begin_;  // per occupied cell, +1 sentinel
  std::vector<std::uint32_t> adj_begin_;   // per occupied cell: range in adj_, +1 sentinel
  std::vector<std::uint32_t> adj_;         // occupied cells among the 27 around each cell
  float cell_f_ = 0;                       // cell, slightly reduced for the fast-path test
  std::vector<std::uint64_t> hash_keys_;   // open addressing, ~0 = empty
  std::vector<std::uint32_t> hash_cells_;
  std::uint64_t hash_mask_ = 0;
  int hash_bits_ = 0;  // log2 of the table's size
  Eigen::Vector3f lo_ = Eigen::Vector3f::Zero();
  double cell_ = 1;
  bool grid_ = true;
  float inv_cell_ = 1;
  std::int32_t dims_[3] = {1, 1, 1};
  struct Tree;
  const Tree& tree() const;  // built on first use, thread-safe
  mutable std::once_flag tree_once_;
  mutable std::unique_ptr<Tree> tree_;
};

//! The index's order of cells: the Morton code of a cell's coordinates (the low 21 bits of x, y
//! and z interleaved). The tiled filter numbers points in this order too (tile_sites.h).
std::uint64_t morton(std::int32_t x, std::int32_t y, std::int32_t z);

namespace detail {
inline std::uint64_t cell_key(std::int32_t x, std::int32_t y, std::int32_t z) {
  return static_cast<std::uint64_t>(x) | (static_cast<std::uint64_t>(y) << 21) |
         (static_cast<std::uint64_t>(z) << 42);
}
}  // namespace detail

template <bool kSlots, class F>
void NeighborIndex::visit(const Eigen::Vector3f& q, float r, F& f) const {
  if (pts_.empty() || !(r > 0)) return;
  const float r2 = r * r;
  std::int32_t lo[3], hi[3];
  // Fast path: every point within r lies in the 27 cells around q's cell, whose occupied
  // members are precomputed per cell.
  if (const std::int64_t cq = adjacent_cell(q, r); cq >= 0) {
    for (std::uint32_t k = adj_begin_[cq], ke = adj_begin_[cq + 1]; k < ke; ++k) {
      const std::uint32_t c = adj_[k];
      scan<kSlots>(cell_begin_[c], cell_begin_[c + 1], q, r2, f);
    }
    return;
  }
  bool grid = grid_;
  for (int a = 0; a < 3 && grid; ++a) {
    const float l = std::floor((q[a] - r - lo_[a]) * inv_cell_);
    const float h = std::floor((q[a] + r - lo_[a]) * inv_cell_);
    if (!(h - l < static_cast<float>(kMaxGridSpan))) grid = false;
  }
  for (int a = 0; a < 3; ++a) {
    if (!grid) break;
    const float l = std::floor((q[a] - r - lo_[a]) * inv_cell_);
    const float h = std::floor((q[a] + r - lo_[a]) * inv_cell_);
    if (h < 0 || l > static_cast<float>(dims_[a] - 1)) return;  // entirely outside
    lo[a] = static_cast<std::int32_t>(std::max(l, 0.0f));
    hi[a] = static_cast<std::int32_t>(std::min(h, static_cast<float>(dims_[a] - 1)));
  }
  if (!grid) {
    std::vector<std::pair<std::uint32_t, float>> found;
    tree_within(q, r, found);
    for (const auto& [i, d2] : found) f(kSlots ? inv_[i] : i, d2);
    return;
  }
  for (std::int32_t z = lo[2]; z <= hi[2]; ++z)
    for (std::int32_t y = lo[1]; y <= hi[1]; ++y)
      for (std::int32_t x = lo[0]; x <= hi[0]; ++x) {
        const std::int64_t c = find_cell(detail::cell_key(x, y, z));
        if (c >= 0) scan<kSlots>(cell_begin_[c], cell_begin_[c + 1], q, r2, f);
      }
}

inline std::int64_t NeighborIndex::adjacent_cell(const Eigen::Vector3f& q, float r) const {
  if (pts_.empty() || !grid_ || !(r <= cell_f_)) return -1;
  std::int32_t c3[3];
  bool inside = true;
  for (int a = 0; a < 3; ++a) {
    const float c = std::floor((q[a] - lo_[a]) * inv_cell_);
    inside = inside && c >= 0 && c <= static_cast<float>(dims_[a] - 1);
    c3[a] = inside ? static_cast<std::int32_t>(c) : 0;
  }
  return inside ? find_cell(detail::cell_key(c3[0], c3[1], c3[2])) : -1;
}

inline int NeighborIndex::cell_octant(const Eigen::Vector3f& q, Eigen::Vector3f& box_lo,
                                      Eigen::Vector3f& box_hi) const {
  int octant = 0;
  const float cell = static_cast<float>(cell_), half = 0.5f * cell, grow = 1e-4f * cell;
  for (int a = 0; a < 3; ++a) {
    const float t = (q[a] - lo_[a]) * inv_cell_, c = std::floor(t);
    const bool upper = t - c >= 0.5f;
    octant |= upper ? 1 << a : 0;
    const float base = lo_[a] + c * cell + (upper ? half : 0.0f);
    box_lo[a] = base - grow;
    box_hi[a] = base + half + grow;
  }
  return octant;
}

template <class F>
bool NeighborIndex::for_each_cell_run(const Eigen::Vector3f& q, float r, F&& f) const {
  if (pts_.empty()) return true;
  if (!grid_) return false;
  const std::int64_t cq = adjacent_cell(q, r);
  if (cq >= 0) {
    for_each_adjacent_run(static_cast<std::size_t>(cq), f);
    return true;
  }
  std::int32_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    const float l = std::floor((q[a] - r - lo_[a]) * inv_cell_);
    const float h = std::floor((q[a] + r - lo_[a]) * inv_cell_);
    if (!(h - l < static_cast<float>(kMaxGridSpan))) return false;
    if (h < 0 || l > static_cast<float>(dims_[a] - 1)) return true;  // nothing near
    lo[a] = static_cast<std::int32_t>(std::max(l, 0.0f));
    hi[a] = static_cast<std::int32_t>(std::min(h, static_cast<float>(dims_[a] - 1)));
  }
  for (std::int32_t z = lo[2]; z <= hi[2]; ++z)
    for (std::int32_t y = lo[1]; y <= hi[1]; ++y)
      for (std::int32_t x = lo[0]; x <= hi[0]; ++x) {
        const std::int64_t c = find_cell(detail::cell_key(x, y, z));
        if (c >= 0) f(cell_begin_[c], cell_begin_[c + 1]);
      }
  return true;
}

//! The grid cell for queries of radius up to r: r and 0.1 % to spare (the cells' float
//! coordinates round). The filter's grids for queries at a known radius are built with it.
inline double grid_cell_for(double r) {
  return r * 1.001;
}
//! Whether a grid of this cell serves queries of radius up to r: its cell at least
//! grid_cell_for(r), so that the 27 cells around a query hold its neighbours, and at most 1.7 r,
//! so that they do not hold many more.
inline bool grid_serves(double cell, double r) {
  return cell >= grid_cell_for(r) && cell <= r * 1.7;
}

//! A rough median distance from a point to its kk-th nearest (itself counted) at `samples` evenly
//! spread points p[k n / samples], k < samples: the (kk / step)-th neighbour in a k-d tree over
//! every step-th point, step = clamp(n / (8 kk), 1, 16). Only to size grids and first query
//! radii; the distances that matter are then measured exactly. 0 for an empty set.
double rough_kth_distance(const std::vector<Eigen::Vector3f>& p, std::size_t kk,
                          std::size_t samples);

}  // namespace scanclean
