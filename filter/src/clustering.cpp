#include "clustering.h"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "neighbor_index.h"
#include "parallel.h"

namespace scanclean::detail {
namespace {

// Open-addressing map from a 63-bit cell key to the head of a list (sequential use only).
class CellMap {
 public:
  explicit CellMap(std::size_t expected) {
    std::size_t cap = 16;
    while (cap < 2 * expected) cap *= 2;
    mask_ = cap - 1;
    keys_.assign(cap, kEmpty);
    vals_.assign(cap, 0);
  }
  // Value slot for key, inserting `init` if absent.
  std::uint32_t& at(std::uint64_t key, std::uint32_t init) {
    std::uint64_t h = (key * 0x9E3779B97F4A7C15ULL) >> 17;
    while (true) {
      const std::uint64_t s = h & mask_;
      if (keys_[s] == key) return vals_[s];
      if (keys_[s] == kEmpty) {
        keys_[s] = key;
        vals_[s] = init;
        return vals_[s];
      }
      ++h;
    }
  }
  const std::uint32_t* find(std::uint64_t key) const {
    std::uint64_t h = (key * 0x9E3779B97F4A7C15ULL) >> 17;
    while (true) {
      const std::uint64_t s = h & mask_;
      if (keys_[s] == key) return &vals_[s];
      if (keys_[s] == kEmpty) return nullptr;
      ++h;
    }
  }

 private:
  static constexpr std::uint64_t kEmpty = ~0ULL;
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> vals_;
  std::uint64_t mask_ = 0;
};

}  // namespace

Clusters cluster_points(const std::vector<Eigen::Vector3d>& x, const Projected& pr, double eps,
                        bool oriented) {
  const std::size_t n = x.size();
  Clusters cl;
  cl.rep_of.assign(n, kNone);
  std::vector<std::uint32_t> cand;
  for (std::size_t i = 0; i < n; ++i)
    if (projected(pr.state[i])) cand.push_back(static_cast<std::uint32_t>(i));
  if (!(eps > 0)) {
    for (std::uint32_t i : cand) {
      cl.rep_of[i] = static_cast<std::uint32_t>(cl.seed.size());
      cl.seed.push_back(i);
      cl.count.push_back(1);
      cl.position.push_back(x[i]);
    }
    return cl;
  }
  {
    std::vector<std::pair<float, std::uint32_t>> key(cand.size());
    for (std::size_t k = 0; k < cand.size(); ++k) key[k] = {-pr.L[cand[k]], cand[k]};
    tbb::parallel_sort(key.begin(), key.end());  // decreasing L, then index: deterministic
    for (std::size_t k = 0; k < cand.size(); ++k) cand[k] = key[k].second;
  }
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max());
  Eigen::Vector3d hi = -lo;
  for (std::uint32_t i : cand) {
    lo = lo.cwiseMin(x[i]);
    hi = hi.cwiseMax(x[i]);
  }
  double cell = 2 * eps;
  if (!cand.empty()) {
    const double extent = (hi - lo).maxCoeff();
    const double max_cells = (1 << 21) - 4;
    if (extent / cell > max_cells) cell = extent / max_cells * (1 + 1e-9);
    lo -= Eigen::Vector3d::Constant(cell);
  }
  auto coord = [&](double v, int a) {
    return static_cast<std::int32_t>(
        std::clamp(std::floor((v - lo[a]) / cell), 0.0, static_cast<double>((1 << 21) - 1)));
  };
  CellMap map(cand.size());
  std::vector<std::uint32_t> next;  // per representative: next one in the same cell
  std::vector<double> lsum;
  const double eps2 = eps * eps;
  for (std::uint32_t i : cand) {
    const Eigen::Vector3d& p = x[i];
    std::uint32_t best = kNone;
    const bool can_join = pr.state[i] != ProjectionState::kNotConverged;
    if (can_join) {
      double best_d2 = eps2;
      std::int32_t a0[3], a1[3];
      for (int a = 0; a < 3; ++a) {
        a0[a] = coord(p[a] - eps, a);
        a1[a] = coord(p[a] + eps, a);
      }
      for (std::int32_t cz = a0[2]; cz <= a1[2]; ++cz)
        for (std::int32_t cy = a0[1]; cy <= a1[1]; ++cy)
          for (std::int32_t cx = a0[0]; cx <= a1[0]; ++cx) {
            const std::uint32_t* head = map.find(cell_key(cx, cy, cz));
            for (std::uint32_t r = head ? *head : kNone; r != kNone; r = next[r]) {
              const std::uint32_t s = cl.seed[r];
              const double d2 = (x[s] - p).squaredNorm();
              if (!(d2 < eps2)) continue;
              if (oriented && !(pr.normal[s].dot(pr.normal[i]) > 0)) continue;
              if (best == kNone || d2 < best_d2 || (d2 == best_d2 && r < best)) {
                best = r;
                best_d2 = d2;
              }
            }
          }
    }
    const double li = std::max(0.0, static_cast<double>(pr.L[i]));
    if (best != kNone) {
      cl.rep_of[i] = best;
      cl.count[best] += 1;
      cl.position[best] += li * p;
      lsum[best] += li;
      continue;
    }
    const auto r = static_cast<std::uint32_t>(cl.seed.size());
    cl.rep_of[i] = r;
    cl.seed.push_back(i);
    cl.count.push_back(1);
    cl.position.push_back(li * p);
    lsum.push_back(li);
    next.push_back(kNone);
    if (can_join) {
      std::uint32_t& head = map.at(cell_key(coord(p[0], 0), coord(p[1], 1), coord(p[2], 2)), kNone);
      next[r] = head;
      head = r;
    }
  }
  for (std::size_t r = 0; r < cl.seed.size(); ++r)
    cl.position[r] = lsum[r] > 0 ? Eigen::Vector3d(cl.position[r] / lsum[r]) : x[cl.seed[r]];
  return cl;
}

}  // namespace scanclean::detail
