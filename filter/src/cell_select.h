#pragma once
//! Internal: radius queries on a NeighborIndex answered from a per-thread cache of grid cell
//! neighbourhoods. The filter queries points in grid order, so consecutive queries mostly fall
//! into the same few cells; the points of a cell's 27 neighbour cells are copied once into a
//! struct of arrays and each query selects from it 8 points at a time (candidate_eval.h
//! select_within: the same float distance test as the index's own loop). The selected slots
//! come in the order NeighborIndex::for_each_slot_within visits them, so results that depend
//! on the order (sums) stay bit-identical.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "neighbor_index.h"

namespace scanclean::detail {

//! A key for one index (unique per call), so that a thread's cache never serves the cells of
//! another index (or of an earlier one at the same address).
std::uint64_t new_cell_cache_key();

class CellSelect {
 public:
  static constexpr std::size_t kNotGrid = std::numeric_limits<std::size_t>::max();
  //! Selects the slots of the index's points within r of q (squared float distance below
  //! r * r), in for_each_slot_within's order, into hits(); returns their count, or kNotGrid
  //! (selecting nothing) when the query does not take the index's grid fast path or its 27
  //! cells hold more than 65,536 points (use the index's own queries then). `key` from
  //! new_cell_cache_key() for this index.
  //! With `parts`, the selection runs over the part of the cell's neighbourhood the query needs
  //! (the points near the octant of the cell that holds q, see part()): the same slots, fewer
  //! distances, but a part costs a pass over the neighbourhood to make, which pays only when
  //! several queries share it.
  std::size_t select(const NeighborIndex& index, std::uint64_t key, const Eigen::Vector3f& q,
                     float r, bool parts = true);
  //! As select, keeping only the slots s that also lie within scale sigma(s) + margin of q
  //! (candidate_eval.h select_within_reach). sigma(s) is read once per cached cell neighbourhood
  //! (the same function for every call with this key).
  template <class Sigma>
  std::size_t select_within_reach(const NeighborIndex& index, std::uint64_t key,
                                  const Eigen::Vector3f& q, float r, Sigma&& sigma, float scale,
                                  float margin) {
    if (!(r > 0)) return 0;
    const std::int64_t c = index.adjacent_cell(q, r);
    Entry* e = c < 0 ? nullptr : entry(index, key, c);
    if (!e) return kNotGrid;
    if (e->sigma.size() != e->n) {
      e->sigma.resize(e->n);
      for (std::size_t k = 0; k < e->n; ++k) e->sigma[k] = sigma(e->slot[k]);
    }
    return select_reach_in(part(index, key, c, *e, q, r), q, r, scale, margin);
  }
  //! The slots of the last select (valid until the next call).
  const std::uint32_t* hits() const { return hit_.data(); }

  //! f(slot) for each slot within r of q, in for_each_slot_within's order, through the cache
  //! when the query takes the grid fast path, else through the index's own query. f must not
  //! use this CellSelect.
  template <class F>
  void for_each_slot_within(const NeighborIndex& index, std::uint64_t key, const Eigen::Vector3f& q,
                            float r, F&& f, bool parts = true) {
    const auto [slots, n] = slots_within(index, key, q, r, parts);
    for (std::size_t k = 0; k < n; ++k) f(slots[k]);
  }
  //! The slots for_each_slot_within visits, as an array (valid until the next call) and their
  //! count.
  std::pair<const std::uint32_t*, std::size_t> slots_within(const NeighborIndex& index,
                                                            std::uint64_t key,
                                                            const Eigen::Vector3f& q, float r,
                                                            bool parts = true) {
    const std::size_t n = select(index, key, q, r, parts);
    if (n != kNotGrid) return {hit_.data(), n};
    hit_.clear();
    index.for_each_slot_within(q, r, [&](std::uint32_t s, float) { hit_.push_back(s); });
    return {hit_.data(), hit_.size()};
  }

 private:
  struct Entry {
    std::uint64_t key = 0;
    std::int64_t cell = -1;
    std::vector<float> x, y, z;  // padded with +inf to a multiple of 8 (first n)
    std::vector<std::uint32_t> slot;
    std::vector<float> sigma;  // per slot, when select_within_reach filled it (else empty)
    std::size_t n = 0;         // the entry's points, padded (the arrays may be longer)
    // A part (the parts_ below): the octant of `cell`, the radius it serves, and whether it
    // copied sigma.
    int octant = -1;
    float reach = 0;
    bool has_sigma = false;
  };
  // The cached neighbourhood of cell c, copied in if absent; null when too crowded.
  Entry* entry(const NeighborIndex& index, std::uint64_t key, std::int64_t c);
  // The part of e (cell c's neighbourhood) that a query at q of radius r needs: the points
  // within kPartReach r of the octant of c that holds q, in e's order, so that a selection from
  // it gives the same slots in the same order. Cached (parts_); e itself when q lies outside its
  // octant's box by rounding.
  const Entry& part(const NeighborIndex& index, std::uint64_t key, std::int64_t c, const Entry& e,
                    const Eigen::Vector3f& q, float r);
  std::size_t select_reach_in(const Entry& e, const Eigen::Vector3f& q, float r, float scale,
                              float margin);
  // One cell of a point grid spans several cells of a coarser grid: keep the last few.
  static constexpr std::size_t kEntries = 8;
  static constexpr std::size_t kMaxPoints = std::size_t{1} << 16;  // per entry
  Entry entry_[kEntries];
  std::size_t next_ = 0;  // round-robin replacement
  // The parts of the entries above: up to eight octants of each.
  static constexpr std::size_t kParts = 4 * kEntries;
  Entry parts_[kParts];
  std::size_t next_part_ = 0;
  std::size_t last_part_ = 0;  // the part the last query took
  std::vector<std::uint32_t> hit_;
};

//! The calling thread's CellSelect.
CellSelect& thread_cell_select();

}  // namespace scanclean::detail
