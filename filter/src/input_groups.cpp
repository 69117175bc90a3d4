#include "input_groups.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <numeric>

#include "fill_later.h"
#include "parallel.h"
#include "radix_sort.h"

namespace scanclean::detail {
namespace {

std::uint64_t bits_of(double v) {
  if (v == 0) v = 0;  // -0 and +0 are one position
  std::uint64_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

// Sorts the points by their source_index attribute and rewrites it through `to_input`.
void remap_sources(PointCloud& cloud, const std::vector<std::size_t>& to_input) {
  Attribute* si = cloud.find_attribute("source_index");
  if (!si) return;
  for (double& v : si->values) v = static_cast<double>(to_input[static_cast<std::size_t>(v)]);
}

PointCloud sorted_by_source(const PointCloud& cloud) {
  const Attribute* si = cloud.find_attribute("source_index");
  std::vector<std::size_t> order(cloud.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  if (si)
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return si->values[a] < si->values[b]; });
  PointCloud out = select(cloud, order);
  out.grid = OrganizedGrid{};
  return out;
}

}  // namespace

Coincident find_coincident(const PointCloud& input) {
  const std::size_t n = input.size();
  if (n == 0) return {};
  const auto& p = input.positions;
  auto same = [&](std::uint32_t a, std::uint32_t b) {
    for (int k = 0; k < 3; ++k)
      if (bits_of(p[a][k]) != bits_of(p[b][k])) return false;
    return true;
  };
  // Records of the hash's top bits above the point's index, sorted stably by those bits: equal
  // positions have equal hashes, so only the points of a run of equal top bits can coincide,
  // and such runs are rare (with 33 bits, about n^2 / 2^34 pairs of distinct points) and short.
  // One 8-byte record a point (a pair of hash and index took 16): half the sort's traffic.
  const int id_bits = std::max(1, static_cast<int>(std::bit_width(n - 1)));  // n >= 1
  const int hash_bits = std::min(33, 64 - id_bits);                          // >= 32
  const std::uint64_t id_mask = (std::uint64_t{1} << id_bits) - 1;
  FillLaterVector<std::uint64_t> key(n);
  parallel_each(n, [&](std::size_t i) {
    std::uint64_t h = 0x9E3779B97F4A7C15ULL;
    for (int k = 0; k < 3; ++k) {
      h ^= bits_of(p[i][k]) + 0x9E3779B97F4A7C15ULL + (h << 6) + (h >> 2);
      h *= 0xBF58476D1CE4E5B9ULL;
      h ^= h >> 31;
    }
    key[i] = (h >> (64 - hash_bits)) << id_bits | i;
  });
  auto top = [id_bits](std::uint64_t e) { return e >> id_bits; };
  auto id = [id_mask](std::uint64_t e) { return static_cast<std::uint32_t>(e & id_mask); };
  {
    FillLaterVector<std::uint64_t> scratch;
    stable_radix_sort(key, top, scratch);
  }
  // Within a run (in index order), each point that equals an earlier head joins the earliest
  // such head; the others are heads. The runs are scanned in parallel chunks (a run belongs to
  // the chunk it starts in), their copies listed per chunk, then in chunk order: the list the
  // scan in one pass gives.
  using Copy = std::pair<std::uint32_t, std::uint32_t>;  // (point, its head)
  constexpr std::size_t kChunk = std::size_t{1} << 16;
  const std::size_t chunks = std::clamp<std::size_t>(n / kChunk, 1, 64);
  std::vector<std::vector<Copy>> found(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    const std::size_t end = n * (c + 1) / chunks;
    std::size_t b = n * c / chunks;
    while (b > 0 && b < end && top(key[b]) == top(key[b - 1])) ++b;  // the first run start
    std::vector<std::uint8_t> is_head;
    while (b < end) {
      std::size_t e = b + 1;
      while (e < n && top(key[e]) == top(key[b])) ++e;
      if (e - b > 1) {
        is_head.assign(e - b, 1);
        for (std::size_t k = b + 1; k < e; ++k)
          for (std::size_t q = b; q < k; ++q)
            if (is_head[q - b] && same(id(key[q]), id(key[k]))) {
              found[c].emplace_back(id(key[k]), id(key[q]));
              is_head[k - b] = 0;
              break;
            }
      }
      b = e;
    }
  });
  std::vector<Copy> copies;
  for (const auto& f : found) copies.insert(copies.end(), f.begin(), f.end());
  Coincident c;
  if (copies.empty()) return c;  // the common case: no copies (and no memory held for them)
  std::vector<std::uint32_t> head(n);
  std::iota(head.begin(), head.end(), 0u);
  for (const auto& [i, h] : copies) head[i] = h;
  c.group_of.resize(n);
  std::vector<std::uint32_t> group_at(n, kNone);
  for (std::size_t i = 0; i < n; ++i) {
    if (head[i] == i) {
      group_at[i] = static_cast<std::uint32_t>(c.first.size());
      c.first.push_back(i);
      c.count.push_back(0);
    }
    c.group_of[i] = group_at[head[i]];
    ++c.count[c.group_of[i]];
  }
  return c;
}

FarSplit split_far_points(const PointCloud& input) {
  FarSplit split;
  const std::size_t n = input.size();
  const std::size_t m = std::min<std::size_t>(n, 10000);
  Eigen::Vector3d lo, hi;
  for (int a = 0; a < 3; ++a) {
    std::vector<double> v(m);
    for (std::size_t k = 0; k < m; ++k) v[k] = input.positions[k * n / m][a];
    const auto q = [&](double f) {
      const auto it = v.begin() + static_cast<std::ptrdiff_t>(f * static_cast<double>(m - 1));
      std::nth_element(v.begin(), it, v.end());
      return *it;
    };
    lo[a] = q(0.01);
    hi[a] = q(0.99);
  }
  const double size = (hi - lo).maxCoeff();
  // A box of zero size (most points at one position) grows by a millimetre.
  const double margin = 4 * std::max(size, 1e-3);
  lo -= Eigen::Vector3d::Constant(margin);
  hi += Eigen::Vector3d::Constant(margin);
  auto inside = [&](std::size_t i) {
    const Eigen::Vector3d& p = input.positions[i];
    return (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all();
  };
  split.near = indices_where<std::size_t>(n, inside);
  split.far = indices_where<std::size_t>(n, [&](std::size_t i) { return !inside(i); });
  // No point in the box: there is no bulk to keep the others apart from (a few points, whose
  // percentiles are single points). One group, so that the far group's own split, which
  // run_split makes next, always has fewer points than the cloud it came from.
  if (split.near.empty()) std::swap(split.near, split.far);
  return split;
}

void expand_coincident(const PointCloud& input, const Coincident& c, FilterResult& r) {
  remap_sources(r.cloud, c.first);
  // Removed: every copy of a removed distinct point, with its flags, in input order.
  const Attribute* si = r.outliers.find_attribute("source_index");
  const Attribute* fl = r.outliers.find_attribute("flags");
  std::vector<double> flag_of(c.first.size(), 0);
  for (std::size_t k = 0; k < r.outliers.size(); ++k)
    flag_of[static_cast<std::size_t>(si->values[k])] = fl->values[k];
  std::vector<std::size_t> idx;
  for (std::size_t i = 0; i < input.size(); ++i)
    if (flag_of[c.group_of[i]] != 0) idx.push_back(i);
  PointCloud ol = select(input, idx);
  ol.grid = OrganizedGrid{};
  std::vector<double> flags(idx.size()), sources(idx.size());
  for (std::size_t k = 0; k < idx.size(); ++k) {
    flags[k] = flag_of[c.group_of[idx[k]]];
    sources[k] = static_cast<double>(idx[k]);
  }
  ol.set_attribute("flags", AttributeType::kUInt8, std::move(flags));
  ol.set_attribute("source_index", AttributeType::kUInt32, std::move(sources));
  r.outliers = std::move(ol);
  r.stats.points_in = input.size();
}

FilterResult merge_parts(std::vector<FilterResult> parts,
                         const std::vector<std::vector<std::size_t>>& indices) {
  FilterResult out;
  out.stats = parts.front().stats;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    remap_sources(parts[k].cloud, indices[k]);
    remap_sources(parts[k].outliers, indices[k]);
    if (k == 0) continue;
    const FilterStats& s = parts[k].stats;
    FilterStats& t = out.stats;
    t.points_in += s.points_in;
    t.points_out += s.points_out;
    t.unsupported += s.unsupported;
    t.low_density += s.low_density;
    t.off_surface += s.off_surface;
    t.low_likelihood += s.low_likelihood;
    t.displaced += s.displaced;
    t.small_components += s.small_components;
    t.merged += s.merged;
    t.kernels += s.kernels;
    t.not_converged += s.not_converged;
    t.seconds_scale += s.seconds_scale;
    t.seconds_kernels += s.seconds_kernels;
    t.seconds_projection += s.seconds_projection;
    t.seconds_clustering += s.seconds_clustering;
    t.seconds_outliers += s.seconds_outliers;
    t.orientation_trees += s.orientation_trees;
    t.seconds_orientation += s.seconds_orientation;
  }
  PointCloud cloud = std::move(parts.front().cloud), outliers = std::move(parts.front().outliers);
  for (std::size_t k = 1; k < parts.size(); ++k) {
    append(cloud, parts[k].cloud);
    append(outliers, parts[k].outliers);
  }
  out.cloud = sorted_by_source(cloud);
  out.outliers = sorted_by_source(outliers);
  return out;
}

}  // namespace scanclean::detail
