#include "cell_select.h"

#include <atomic>

#include "candidate_eval.h"
#include "select.h"

namespace scanclean::detail {
namespace {

// A part holds the points within this factor of the radius of the query that made it; a later
// query of a larger radius makes it again.
constexpr float kPartReach = 1.15f;
// Parts only for queries whose part reach is at most this many cells.
constexpr float kMaxPartReach = 0.95f;
constexpr std::size_t kMaxPartPoints = std::size_t{1} << 14;

}  // namespace

std::uint64_t new_cell_cache_key() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1);
}

CellSelect::Entry* CellSelect::entry(const NeighborIndex& index, std::uint64_t key,
                                     std::int64_t c) {
  // An entry is made only where none matches: at most one does.
  Entry* found = nullptr;
  for (Entry& e : entry_)
    if (e.cell == c && e.key == key) {
      found = &e;
      break;
    }
  if (found == nullptr) {
    // A neighbourhood too large to copy (data concentrated in few cells): the index's own
    // query, so that the cache stays within kEntries x kMaxPoints x 16 bytes per thread.
    std::size_t total = 0;
    index.for_each_adjacent_run(static_cast<std::size_t>(c),
                                [&](std::uint32_t b, std::uint32_t end) { total += end - b; });
    if (total > kMaxPoints) return nullptr;
    found = &entry_[next_];
    next_ = (next_ + 1) % kEntries;
    Entry& e = *found;
    e.key = key;
    e.cell = c;
    // The arrays only grow (no clearing): n says how much of them is the entry.
    e.n = (total + 7) / 8 * 8;
    if (e.x.size() < e.n) {
      e.x.resize(e.n);
      e.y.resize(e.n);
      e.z.resize(e.n);
      e.slot.resize(e.n);
    }
    e.sigma.clear();
    // The index's points lie one after the other in slot order (x, y, z each).
    static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
    std::size_t k = 0;
    index.for_each_adjacent_run(static_cast<std::size_t>(c),
                                [&](std::uint32_t b, std::uint32_t end) {
                                  if (end <= b) return;
                                  split_run(index.slot_point(b).data(), end - b, b, e.x.data() + k,
                                            e.y.data() + k, e.z.data() + k, e.slot.data() + k);
                                  k += end - b;
                                });
    const float inf = std::numeric_limits<float>::infinity();
    for (; k < e.n; ++k) {
      e.x[k] = e.y[k] = e.z[k] = inf;
      e.slot[k] = 0;
    }
  }
  return found;
}

const CellSelect::Entry& CellSelect::part(const NeighborIndex& index, std::uint64_t key,
                                          std::int64_t c, const Entry& e, const Eigen::Vector3f& q,
                                          float r) {
  // A part keeps the points within reach of an octant's box, half a cell wide, out of the 27
  // cells: with reach near a cell it keeps most of them, and making it costs more than it
  // saves (the 1M-point sphere at defaults, where the gathers' radius is the kernel grid's
  // cell).
  const float reach = std::max(std::min(r * kPartReach, index.max_adjacent_radius()), r);
  if (reach > kMaxPartReach * static_cast<float>(index.cell())) return e;
  // Memory: parts of at most kMaxPartPoints points, at most kParts x kMaxPartPoints x 20 bytes
  // a thread.
  if (e.n > kMaxPartPoints) return e;
  Eigen::Vector3f lo, hi;
  const int octant = index.cell_octant(q, lo, hi);
  if (!((q.array() >= lo.array()).all() && (q.array() <= hi.array()).all())) return e;
  const bool sigma = !e.sigma.empty();
  // A part is made (or made again in place) only where none matches: at most one does.
  // Consecutive queries mostly fall into the same octant: the part of the last one first.
  auto matches = [&](const Entry& p) { return p.cell == c && p.octant == octant && p.key == key; };
  Entry* found = matches(parts_[last_part_]) ? &parts_[last_part_] : nullptr;
  for (std::size_t k = 0; k < kParts && !found; ++k)
    if (matches(parts_[k])) found = &parts_[k];
  const bool usable = found && found->reach >= r && found->has_sigma == sigma;
  if (!found) {
    found = &parts_[next_part_];
    next_part_ = (next_part_ + 1) % kParts;
  }
  last_part_ = static_cast<std::size_t>(found - parts_);
  if (usable) return *found;
  Entry& p = *found;
  p.key = key;
  p.cell = c;
  p.octant = octant;
  p.has_sigma = sigma;
  p.reach = reach;
  // select_near_box keeps every point within reach of a query inside the box; 0.1 % more to
  // spare.
  const float w2 = p.reach * p.reach * 1.001f;
  const float blo[3] = {lo.x(), lo.y(), lo.z()}, bhi[3] = {hi.x(), hi.y(), hi.z()};
  // The arrays only grow (no clearing): n says how much of them is the part.
  const std::size_t cap = e.n + kStoreSlack;
  if (p.x.size() < cap) {
    p.x.resize(cap);
    p.y.resize(cap);
    p.z.resize(cap);
    p.slot.resize(cap);
  }
  if (sigma && p.sigma.size() < cap) p.sigma.resize(cap);
  std::size_t m = 0;
  select_near_box(
      e.x.data(), e.y.data(), e.z.data(), e.slot.data(), sigma ? e.sigma.data() : nullptr, e.n, blo,
      bhi, w2,
      {p.x.data(), p.y.data(), p.z.data(), p.slot.data(), sigma ? p.sigma.data() : nullptr}, m);
  // Padded as the entries are: +inf coordinates.
  const float inf = std::numeric_limits<float>::infinity();
  p.n = (m + 7) / 8 * 8;
  for (std::size_t k = m; k < p.n; ++k) {
    p.x[k] = p.y[k] = p.z[k] = inf;
    p.slot[k] = 0;
    if (sigma) p.sigma[k] = 0;
  }
  return p;
}

std::size_t CellSelect::select(const NeighborIndex& index, std::uint64_t key,
                               const Eigen::Vector3f& q, float r, bool parts) {
  if (!(r > 0)) return 0;  // as NeighborIndex::for_each_slot_within
  const std::int64_t c = index.adjacent_cell(q, r);
  const Entry* full = c < 0 ? nullptr : entry(index, key, c);
  if (!full) return kNotGrid;
  const Entry& e = parts ? part(index, key, c, *full, q, r) : *full;
  if (hit_.size() < e.n) hit_.resize(e.n);
  const float origin[3] = {q.x(), q.y(), q.z()};
  return select_within(e.x.data(), e.y.data(), e.z.data(), e.slot.data(), e.n, origin, r * r,
                       hit_.data());
}

std::size_t CellSelect::select_reach_in(const Entry& e, const Eigen::Vector3f& q, float r,
                                        float scale, float margin) {
  if (hit_.size() < e.n) hit_.resize(e.n);
  const float origin[3] = {q.x(), q.y(), q.z()};
  return detail::select_within_reach(e.x.data(), e.y.data(), e.z.data(), e.sigma.data(),
                                     e.slot.data(), e.n, origin, r * r, scale, margin, hit_.data());
}

CellSelect& thread_cell_select() {
  thread_local CellSelect s;
  return s;
}

}  // namespace scanclean::detail
