#include "outputs.h"

#include <tbb/combinable.h>
#include <tbb/parallel_invoke.h>

#include <array>
#include <cmath>
#include <cstddef>

#include "huge_pages.h"
#include "parallel.h"

namespace scanclean::detail {

void write_outputs(const OutputInput& in, FilterResult& result) {
  const PointCloud& input = *in.input;
  const Clusters& cl = *in.clusters;
  const std::vector<Removal>& rep_drop = *in.removal;
  const Projected& pr = *in.projected;
  const std::vector<std::uint32_t>& src = *in.input_index;
  const Eigen::Vector3d& origin = in.origin;
  FilterStats& st = result.stats;
  const std::size_t N = input.size();
  const std::size_t R = cl.seed.size();
  auto mult = [&](std::size_t s) -> std::size_t {
    return in.multiplicity ? (*in.multiplicity)[src[s]] : 1;
  };
  // Input points each representative stands for: its members, or with coincident copies the
  // copies its members stand for.
  std::vector<std::uint64_t> copies;
  if (in.multiplicity) {
    copies.assign(R, 0);
    for (std::size_t s = 0; s < N; ++s)
      if (cl.rep_of[s] != kNone) copies[cl.rep_of[s]] += mult(s);
  }
  auto members = [&](std::uint32_t r) -> std::uint64_t {
    return in.multiplicity ? copies[r] : cl.count[r];
  };
  // Output points in the input order of their seeds (seeds are distinct input points).
  std::vector<std::uint32_t> kept;
  {
    std::vector<std::uint32_t> rep_at(N, kNone);
    parallel_each(R, [&](std::size_t r) {
      if (rep_drop[r] == Removal::kKept) rep_at[src[cl.seed[r]]] = static_cast<std::uint32_t>(r);
    });
    kept = indices_where(N, [&](std::size_t i) { return rep_at[i] != kNone; });
    parallel_each(kept.size(), [&](std::size_t k) { kept[k] = rep_at[kept[k]]; });
  }
  {
    std::vector<std::uint32_t> seeds_s(kept.size());  // in the filter's order
    std::vector<std::size_t> seeds(kept.size());      // input indices
    parallel_each(kept.size(), [&](std::size_t k) {
      seeds_s[k] = cl.seed[kept[k]];
      seeds[k] = src[seeds_s[k]];
    });
    PointCloud& out = result.cloud;
    out = select(input, seeds);
    out.grid = OrganizedGrid{};
    // The attribute arrays are zeroed as they are made (std::vector): seven arrays of up to 8
    // bytes a point, zeroed side by side.
    const std::size_t nk = kept.size();
    std::vector<double> L, it, fl, mc, si, dn;
    tbb::parallel_invoke([&] { resize_huge(out.normals, nk); }, [&] { resize_huge(L, nk); },
                         [&] { resize_huge(it, nk); }, [&] { resize_huge(fl, nk); },
                         [&] { resize_huge(mc, nk); }, [&] { resize_huge(si, nk); },
                         [&] { resize_huge(dn, nk); });
    // The representatives and their seeds are scattered over memory: each output point's are
    // fetched a few points ahead (the loads are independent, so they overlap).
    constexpr std::size_t kAhead = 8;
    parallel_each(kept.size(), [&](std::size_t k) {
      if (k + kAhead < kept.size()) {
        const std::uint32_t ra = kept[k + kAhead], sa = seeds_s[k + kAhead];
        __builtin_prefetch(&cl.position[ra]);
        __builtin_prefetch(&cl.count[ra]);
        __builtin_prefetch(&pr.normal[sa]);
        __builtin_prefetch(&pr.L[sa]);
        __builtin_prefetch(&pr.iterations[sa]);
        __builtin_prefetch(&pr.state[sa]);
      }
      const std::uint32_t r = kept[k], s = seeds_s[k];
      out.positions[k] = cl.position[r] + origin;
      out.normals[k] = pr.normal[s];
      L[k] = pr.L[s];
      it[k] = pr.iterations[s];
      fl[k] = pr.state[s] == ProjectionState::kNotConverged ? kFlagNotConverged : 0;
      mc[k] = static_cast<double>(members(r));
      si[k] = src[s];
      // How far the filter moved the point: from its seed's input position, along the normal.
      dn[k] = (out.positions[k] - input.positions[src[s]]).dot(pr.normal[s].cast<double>());
    });
    if (input.has_colors()) {
      // A merged point takes the mean colour of the input points it stands for (coincident
      // copies count with their first copy's colour).
      std::vector<std::array<double, 5>> acc(R, std::array<double, 5>{0, 0, 0, 0, 0});
      for (std::size_t s = 0; s < N; ++s) {
        const std::uint32_t r = cl.rep_of[s];
        if (r == kNone || rep_drop[r] != Removal::kKept) continue;
        const double m = static_cast<double>(mult(s));
        const auto& c = input.colors[src[s]];
        for (int ch = 0; ch < 4; ++ch) acc[r][ch] += m * c[ch];
        acc[r][4] += m;
      }
      for (std::size_t k = 0; k < kept.size(); ++k) {
        const auto& a = acc[kept[k]];
        if (a[4] > 0)
          for (int ch = 0; ch < 4; ++ch)
            out.colors[k][ch] = static_cast<std::uint8_t>(std::lround(a[ch] / a[4]));
      }
    }
    out.set_attribute("likelihood", AttributeType::kFloat32, std::move(L));
    out.set_attribute("iterations", AttributeType::kUInt8, std::move(it));
    out.set_attribute("flags", AttributeType::kUInt8, std::move(fl));
    out.set_attribute("merge_count", AttributeType::kUInt32, std::move(mc));
    out.set_attribute("source_index", AttributeType::kUInt32, std::move(si));
    out.set_attribute("displacement", AttributeType::kFloat32, std::move(dn));
    st.points_out = kept.size();
    for (std::uint32_t r : kept) st.merged += members(r) - 1;
  }
  {
    // Each point's flag (src maps the filter's points to distinct input points) and why it was
    // removed, counted per thread and added up: integer counts, the same in any order.
    struct Removed {
      std::size_t unsupported = 0, off_surface = 0, low_density = 0, small_components = 0,
                  low_likelihood = 0, displaced = 0;
    };
    std::vector<std::uint8_t> in_flag(N, 0);
    tbb::combinable<Removed> removed;
    parallel_each(N, [&](std::size_t s) {
      Removed& c = removed.local();
      switch (pr.state[s]) {
        case ProjectionState::kUnsupported:
          in_flag[src[s]] = kFlagUnsupported;
          c.unsupported += mult(s);
          return;
        case ProjectionState::kOffSurface:
          in_flag[src[s]] = kFlagOutlier;
          c.off_surface += mult(s);
          return;
        case ProjectionState::kSparse:
          in_flag[src[s]] = kFlagOutlier;
          c.low_density += mult(s);
          return;
        case ProjectionState::kConverged:
        case ProjectionState::kNotConverged:
          break;
      }
      const Removal why = rep_drop[cl.rep_of[s]];
      if (why == Removal::kKept) return;
      in_flag[src[s]] = static_cast<std::uint8_t>(
          kFlagOutlier | (pr.state[s] == ProjectionState::kNotConverged ? kFlagNotConverged : 0));
      switch (why) {
        case Removal::kSmallComponent:
          c.small_components += mult(s);
          break;
        case Removal::kLowLikelihood:
          c.low_likelihood += mult(s);
          break;
        case Removal::kDisplaced:
          c.displaced += mult(s);
          break;
        case Removal::kLowDensity:
        case Removal::kKept:
          c.low_density += mult(s);
          break;
      }
    });
    removed.combine_each([&](const Removed& c) {
      st.unsupported += c.unsupported;
      st.off_surface += c.off_surface;
      st.low_density += c.low_density;
      st.small_components += c.small_components;
      st.low_likelihood += c.low_likelihood;
      st.displaced += c.displaced;
    });
    const std::vector<std::size_t> idx =
        indices_where<std::size_t>(N, [&](std::size_t i) { return in_flag[i] != 0; });
    PointCloud& ol = result.outliers;
    ol = select(input, idx);
    ol.grid = OrganizedGrid{};
    std::vector<double> fl(idx.size()), si(idx.size());
    for (std::size_t k = 0; k < idx.size(); ++k) {
      fl[k] = in_flag[idx[k]];
      si[k] = static_cast<double>(idx[k]);
    }
    ol.set_attribute("flags", AttributeType::kUInt8, std::move(fl));
    ol.set_attribute("source_index", AttributeType::kUInt32, std::move(si));
  }
}

}  // namespace scanclean::detail
