#include "cell_select.h"

#include <atomic>

#include "candidate_eval.h"

namespace scanclean::detail {

std::uint64_t new_cell_cache_key() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1);
}

CellSelect::Entry* CellSelect::entry(const NeighborIndex& index, std::uint64_t key,
                                     std::int64_t c) {
  Entry* found = nullptr;
  for (Entry& e : entry_)
    if (e.cell == c && e.key == key) found = &e;
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
    e.x.clear();
    e.y.clear();
    e.z.clear();
    e.slot.clear();
    e.sigma.clear();
    index.for_each_adjacent_run(static_cast<std::size_t>(c),
                                [&](std::uint32_t b, std::uint32_t end) {
                                  for (std::uint32_t s = b; s < end; ++s) {
                                    const Eigen::Vector3f& p = index.slot_point(s);
                                    e.x.push_back(p.x());
                                    e.y.push_back(p.y());
                                    e.z.push_back(p.z());
                                    e.slot.push_back(s);
                                  }
                                });
    const float inf = std::numeric_limits<float>::infinity();
    while (e.x.size() % 8 != 0) {
      e.x.push_back(inf);
      e.y.push_back(inf);
      e.z.push_back(inf);
      e.slot.push_back(0);
    }
  }
  return found;
}

std::size_t CellSelect::select(const NeighborIndex& index, std::uint64_t key,
                               const Eigen::Vector3f& q, float r) {
  if (!(r > 0)) return 0;  // as NeighborIndex::for_each_slot_within
  const std::int64_t c = index.adjacent_cell(q, r);
  const Entry* e = c < 0 ? nullptr : entry(index, key, c);
  if (!e) return kNotGrid;
  if (hit_.size() < e->x.size()) hit_.resize(e->x.size());
  const float origin[3] = {q.x(), q.y(), q.z()};
  return select_within(e->x.data(), e->y.data(), e->z.data(), e->slot.data(), e->x.size(), origin,
                       r * r, hit_.data());
}

std::size_t CellSelect::select_reach_in(const Entry& e, const Eigen::Vector3f& q, float r,
                                        float scale, float margin) {
  if (hit_.size() < e.x.size()) hit_.resize(e.x.size());
  const float origin[3] = {q.x(), q.y(), q.z()};
  return detail::select_within_reach(e.x.data(), e.y.data(), e.z.data(), e.sigma.data(),
                                     e.slot.data(), e.x.size(), origin, r * r, scale, margin,
                                     hit_.data());
}

CellSelect& thread_cell_select() {
  thread_local CellSelect s;
  return s;
}

}  // namespace scanclean::detail
