// The tiled, out-of-core driver of the robust filter (tiled_filter.h): the passes over the
// input in the order the header lists them, each in its own file pair: tile_globals (passes
// 1-3), tile_plan, tile_sites (pass 4), tile_scratch (pass 5) and tile_exchange (what the
// processes share); pass 6 filters each tile with robust_filter.
#include "scanclean/filter/tiled_filter.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "kernels.h"
#include "parallel.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/process_memory.h"
#include "tile_exchange.h"
#include "tile_globals.h"
#include "tile_plan.h"
#include "tile_scratch.h"
#include "tile_sites.h"

namespace scanclean {
namespace {

using detail::Clock;
using detail::seconds_since;

// The part of a tile's result whose points are the tile's own, with record numbers as
// source_index.
PointCloud own_part(const PointCloud& c, const std::vector<std::uint8_t>& own,
                    const std::vector<std::uint64_t>& records) {
  const Attribute* si = c.find_attribute("source_index");
  if (!si) throw std::logic_error("tiled filter: a result without source_index");
  std::vector<std::size_t> keep;
  for (std::size_t k = 0; k < c.size(); ++k)
    if (own[static_cast<std::size_t>(si->values[k])]) keep.push_back(k);
  PointCloud part = select(c, keep);
  std::erase_if(part.attributes,
                [](const Attribute& a) { return a.name == detail::kKernelSitesAttribute; });
  Attribute* s = part.find_attribute("source_index");
  for (double& v : s->values) v = static_cast<double>(records[static_cast<std::size_t>(v)]);
  return part;
}

}  // namespace

void validate(const TiledOptions& t) {
  if (t.memory_budget < (std::size_t{64} << 20))
    throw OptionError("--memory-budget: expected at least 64 MiB, got " +
                      std::to_string(t.memory_budget >> 20) + " MiB");
  if (!(t.halo_factor >= 1 && t.halo_factor <= 20))
    throw OptionError("--halo: expected a number in [1, 20], got " + std::to_string(t.halo_factor));
  if (t.chunk_records == 0) throw OptionError("tiled filter: chunk_records must be > 0");
}

// Measured on the scaling benchmark's scenes (docs/SCALING.md): the filter's own peak
// plus the tile's input and result copies, about 330 bytes per point, and 192 MiB for the
// histogram, the read buffers and the program.
namespace {
// The filter's bytes per point with that many attributes (three copies of a double each).
std::uint64_t bytes_per_point(std::size_t attributes) {
  return 330 + 24 * std::uint64_t{attributes};
}
}  // namespace

std::uint64_t tile_point_limit(std::size_t budget, std::size_t attributes) {
  const std::uint64_t fixed = std::uint64_t{192} << 20;
  return budget > fixed + (std::uint64_t{16} << 20) ? (budget - fixed) / bytes_per_point(attributes)
                                                    : 50000;
}

std::uint64_t in_memory_bytes(std::uint64_t points, std::size_t attributes) {
  return points * bytes_per_point(attributes) + (std::uint64_t{64} << 20);
}

TiledStats tiled_filter(const TiledSource& src, const FilterOptions& o, const TiledOptions& t,
                        const TileSink& sink, const TileComm& comm) {
  validate(o);
  validate(t);
  if (o.scale_regions > 0)
    throw OptionError(
        "--scale-regions: a scale per region needs the whole cloud in memory; it cannot run "
        "tiled (raise --memory-budget)");
  if (o.orient_k > 0)
    throw OptionError(
        "orient_k: orienting normals needs the whole cloud in memory; it cannot run tiled "
        "(raise --memory-budget)");
  const auto t_start = Clock::now();
  auto progress = [&](const std::string& phase, double f) {
    if (t.progress) t.progress(phase, f);
  };
  TiledStats st;
  const std::array<std::uint64_t, 2> range = detail::record_range(src.records, comm);

  // Passes 1-3: the global choices (tile_globals.h).
  detail::GlobalPasses g =
      detail::global_passes(src, o, t.halo_factor, range, t.chunk_records, comm, t.progress);
  const TiledGlobals& gl = st.globals = g.globals;
  st.points_in = gl.points;
  if (gl.points == 0) return st;
  st.seconds_globals = seconds_since(t_start);
  if (t.on_globals) t.on_globals(gl);

  // The tile plan (tile_plan.h); pass 4 (kernel stride > 1): the kernel sites (tile_sites.h);
  // pass 5: every point into the scratch files of its tiles (tile_scratch.h).
  auto t_dist = Clock::now();
  const std::uint64_t limit = t.max_tile_points > 0
                                  ? t.max_tile_points
                                  : tile_point_limit(t.memory_budget, g.columns.attributes.size());
  const detail::TilePlan plan = detail::plan_tiles(g.grid, g.histogram, gl.halo, limit, comm.ranks);
  std::vector<std::uint64_t>().swap(g.histogram);
  st.tiles = plan.tiles.size();
  const std::uint64_t stride = static_cast<std::uint64_t>(std::max(1, gl.kernel_stride));
  const bool want_sites = stride > 1 && o.scale != ScaleMode::kAdaptive;
  std::optional<detail::KernelSites> sites;
  if (want_sites) {
    progress("kernel sites", 0);
    sites.emplace(src, range, t.chunk_records, comm, gl.box,
                  detail::kernel_site_cell(gl.h, gl.h0, g.r_est), stride);
  }
  progress("distributing", 0);
  const detail::ScratchCleanup cleanup(t.scratch, plan.tiles.size(), comm.ranks);
  {
    const std::size_t T = plan.tiles.size();
    const std::size_t flush_at = std::clamp<std::size_t>(
        t.memory_budget / 16 / std::max<std::size_t>(1, T), 4096, std::size_t{1} << 20);
    detail::ScratchWriter scratch(t.scratch, T, comm.rank, flush_at);
    const detail::HaloLookup halo(plan, gl.box, gl.halo);
    std::vector<std::uint32_t> hits;
    std::uint64_t done = 0;
    const std::uint64_t my_records = range[1] - range[0] + 1;
    detail::stream_records(src, range[0], range[1], t.chunk_records,
                           [&](const PointCloud& c, const std::vector<std::uint64_t>& rec) {
                             detail::check_columns(c, g.columns);
                             for (std::size_t i = 0; i < c.size(); ++i) {
                               halo.tiles_of(c.positions[i], hits);
                               std::uint64_t tagged = rec[i];
                               if (sites && sites->next_is_site(c.positions[i]))
                                 tagged |= detail::kSiteBit;
                               for (std::uint32_t k : hits) scratch.put(k, c, i, tagged, g.columns);
                             }
                             done += c.size();
                             progress("distributing",
                                      static_cast<double>(done) / static_cast<double>(my_records));
                           });
    scratch.finish();
  }
  detail::allgather(comm, {});  // every process's scratch files are complete
  st.seconds_distribute = seconds_since(t_dist);
  sites.reset();

  // Pass 6: the tiles of this process, each with the global choices.
  auto t_tiles = Clock::now();
  FilterOptions to = o;
  to.progress = nullptr;
  if (o.scale == ScaleMode::kAuto) {
    to.scale = ScaleMode::kFixed;
    to.h = gl.h;
    to.refit_noise_sigma = gl.noise_sigma;  // the refit's, as the in-memory run's
  }
  to.kernel_stride = gl.kernel_stride;
  to.merge_eps = gl.merge_eps;
  to.min_component_size = gl.min_component_size;
  // With comm.take the processes take the tiles one at a time, largest first, each as it
  // becomes free: a tile's time is not its points' (density, clutter, the machine's other
  // work). Else this process filters the tiles the plan gave it, in tile order.
  const bool taking = comm.ranks > 1 && comm.take;
  const std::vector<std::size_t> order =
      taking ? detail::largest_first(plan) : std::vector<std::size_t>{};
  std::size_t mine_total = 0, mine_done = 0, next = 0;  // (the plan's share)
  if (!taking)
    for (const auto& e : plan.tiles) mine_total += e.rank == comm.rank ? 1 : 0;
  auto next_tile = [&]() -> std::optional<std::size_t> {
    if (taking) {
      const std::uint64_t j = comm.take();
      if (j >= order.size()) return std::nullopt;
      progress("tiles", static_cast<double>(j) / static_cast<double>(order.size()));
      return order[static_cast<std::size_t>(j)];
    }
    while (next < plan.tiles.size() && plan.tiles[next].rank != comm.rank) ++next;
    if (next == plan.tiles.size()) return std::nullopt;
    return next++;
  };
  while (const std::optional<std::size_t> taken = next_tile()) {
    const std::size_t k = *taken;
    PointCloud c;
    std::vector<std::uint64_t> rec;
    for (int r = 0; r < std::max(1, comm.ranks); ++r) {
      const std::filesystem::path file = detail::scratch_file(t.scratch, k, r);
      detail::read_points(file, g.columns, c, rec);
      std::error_code ec;
      std::filesystem::remove(file, ec);
    }
    if (want_sites) {
      std::vector<double> site(rec.size());
      for (std::size_t i = 0; i < rec.size(); ++i) {
        site[i] = (rec[i] & detail::kSiteBit) ? 1.0 : 0.0;
        rec[i] &= ~detail::kSiteBit;
      }
      c.set_attribute(detail::kKernelSitesAttribute, AttributeType::kUInt8, std::move(site));
    }
    std::vector<std::uint8_t> own(c.size(), 0);
    std::uint64_t own_n = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
      own[i] = plan.tile_of(c.positions[i]) == k ? 1 : 0;
      own_n += own[i];
    }
    st.halo_points += c.size() - own_n;
    st.tile_points_max = std::max<std::uint64_t>(st.tile_points_max, c.size());
    PointCloud out, outl;
    if (own_n > 0) {
      const FilterResult r = robust_filter(c, to);
      out = own_part(r.cloud, own, rec);
      outl = own_part(r.outliers, own, rec);
    }
    st.points_out += out.size();
    st.outliers += outl.size();
    if (const Attribute* mc = out.find_attribute("merge_count"))
      for (double v : mc->values) st.merged += static_cast<std::uint64_t>(v) - 1;
    if (const Attribute* fl = outl.find_attribute("flags"))
      for (double v : fl->values)
        st.unsupported += (static_cast<int>(v) & kFlagUnsupported) ? 1 : 0;
    sink(k, out, outl);
    ++st.tiles_here;
    if (!taking)
      progress("tiles", static_cast<double>(++mine_done) /
                            static_cast<double>(std::max<std::size_t>(1, mine_total)));
  }
  if (taking) progress("tiles", 1.0);  // every tile taken
  st.seconds_tiles = seconds_since(t_tiles);
  // Totals over every process.
  if (comm.ranks > 1) {
    detail::MessageWriter mine;
    for (std::uint64_t v : {st.points_out, st.outliers, st.unsupported, st.merged})
      mine.put<std::uint64_t>(v);
    std::uint64_t sums[4] = {0, 0, 0, 0};
    for (const std::string& m : detail::allgather(comm, mine.bytes)) {
      detail::MessageReader r{m};
      for (auto& s : sums) s += r.get<std::uint64_t>();
    }
    st.points_out = sums[0];
    st.outliers = sums[1];
    st.unsupported = sums[2];
    st.merged = sums[3];
  }
  st.seconds_total = seconds_since(t_start);
  st.peak_rss_bytes = peak_resident_bytes();
  return st;
}

}  // namespace scanclean
