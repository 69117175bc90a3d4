// The tiled, out-of-core driver of the robust filter (tiled_filter.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "input_checks.h"
#include "kernels.h"
#include "neighbor_index.h"
#include "parallel.h"
#include "point_set.h"
#include "scanclean/core/errors.h"
#include "scanclean/filter/tiled_filter.h"
#include "select.h"
#include "tile_scale.h"

namespace scanclean {
namespace {

using detail::Clock;
using detail::seconds_since;

// ---- bytes: a tiny serializer for what the processes exchange ----

struct Bytes {
  std::string s;
  template <class T>
  void put(const T& v) {
    s.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  template <class T>
  void put_vec(const std::vector<T>& v) {
    put<std::uint64_t>(v.size());
    s.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }
};

struct Reader {
  const std::string& s;
  std::size_t at = 0;
  bool done() const { return at >= s.size(); }
  template <class T>
  T get() {
    if (at + sizeof(T) > s.size()) throw std::logic_error("tiled filter: short message");
    T v;
    std::memcpy(static_cast<void*>(&v), s.data() + at, sizeof(T));
    at += sizeof(T);
    return v;
  }
  template <class T>
  std::vector<T> get_vec() {
    const auto n = get<std::uint64_t>();
    if (at + n * sizeof(T) > s.size()) throw std::logic_error("tiled filter: short message");
    std::vector<T> v(n);
    if (n > 0) std::memcpy(v.data(), s.data() + at, n * sizeof(T));  // (an empty v has no data)
    at += n * sizeof(T);
    return v;
  }
};

// Every process's message, in rank order.
std::vector<std::string> allgather(const TileComm& comm, const std::string& mine) {
  if (comm.ranks <= 1 || !comm.allgather) return {mine};
  Bytes framed;
  framed.put<std::uint64_t>(mine.size());
  framed.s += mine;
  const std::string all = comm.allgather(framed.s);
  std::vector<std::string> out;
  Reader r{all};
  while (!r.done()) {
    const auto n = r.get<std::uint64_t>();
    out.push_back(all.substr(r.at, n));
    r.at += n;
  }
  if (out.size() != static_cast<std::size_t>(comm.ranks))
    throw std::logic_error("tiled filter: allgather returned the wrong number of messages");
  return out;
}

std::array<std::uint64_t, 2> my_range(std::uint64_t records, const TileComm& comm) {
  const auto n = static_cast<std::uint64_t>(std::max(1, comm.ranks));
  const auto at = [&](std::uint64_t k) { return records / n * k + records % n * k / n; };
  return {at(static_cast<std::uint64_t>(comm.rank)), at(static_cast<std::uint64_t>(comm.rank) + 1)};
}

std::size_t peak_rss() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("VmHWM:", 0) == 0)
      return static_cast<std::size_t>(std::stoull(line.substr(6))) * 1024;
  return 0;
}

// Streams records [b, e) of the source in chunks.
template <class F>
void stream(const TiledSource& src, std::uint64_t b, std::uint64_t e, std::size_t chunk, F&& f) {
  PointCloud c;
  std::vector<std::uint64_t> rec;
  for (std::uint64_t at = b; at < e; at += chunk) {
    src.read(at, std::min<std::uint64_t>(chunk, e - at), c, rec);
    f(c, rec);
  }
}

// ---- the occupancy histogram and the tile plan ----

struct Grid {
  Eigen::Vector3d lo = Eigen::Vector3d::Zero();
  double cell = 1;
  std::array<std::int64_t, 3> dims{1, 1, 1};
  std::size_t cells() const { return static_cast<std::size_t>(dims[0] * dims[1] * dims[2]); }
  std::array<std::int64_t, 3> cell_of(const Eigen::Vector3d& p) const {
    std::array<std::int64_t, 3> c{};
    for (int a = 0; a < 3; ++a)
      c[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor((p[a] - lo[a]) / cell)),
                                      0, dims[a] - 1);
    return c;
  }
  std::size_t flat(const std::array<std::int64_t, 3>& c) const {
    return static_cast<std::size_t>((c[2] * dims[1] + c[1]) * dims[0] + c[0]);
  }
};

Grid make_grid(const Eigen::AlignedBox3d& box) {
  Grid g;
  g.lo = box.min();
  const Eigen::Vector3d ext = box.diagonal().cwiseMax(0.0);
  const double emax = ext.maxCoeff();
  if (!(emax > 0)) return g;  // a single location: one cell
  const double vol = std::max(ext.x(), emax * 1e-6) * std::max(ext.y(), emax * 1e-6) *
                     std::max(ext.z(), emax * 1e-6);
  g.cell = std::max(emax / 256.0, std::cbrt(vol / 2.0e6));
  for (int a = 0; a < 3; ++a)
    g.dims[a] = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(ext[a] / g.cell)));
  return g;
}

// ---- the in-memory run's kernel subsample (kernels.h: every stride-th point in grid order) ----

// The grid of the point index the in-memory run's kernels phase uses over the whole cloud (cell
// given, float coordinates relative to the box centre, anchored half a cell below their minimum:
// the arithmetic of NeighborIndex's constructor), so that a point's cell, hence its place in the
// whole cloud's grid order, is known from the first pass's box and h alone.
struct SiteGrid {
  Eigen::Vector3f lo = Eigen::Vector3f::Zero();
  float inv_cell = 1;
  std::int32_t dims[3] = {1, 1, 1};
  std::uint64_t code(const Eigen::Vector3f& p) const {
    std::int32_t c[3];
    for (int a = 0; a < 3; ++a) {
      const float f = std::floor((p[a] - lo[a]) * inv_cell);
      c[a] = static_cast<std::int32_t>(std::clamp(f, 0.0f, static_cast<float>(dims[a] - 1)));
    }
    return morton(c[0], c[1], c[2]);  // the index's own cell order
  }
};

SiteGrid site_grid(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& origin, double cell) {
  SiteGrid g;
  // Rounding is monotonic: the smallest float coordinate is the float of the smallest one.
  const Eigen::Vector3f lo = (box.min() - origin).cast<float>();
  const Eigen::Vector3f hi = (box.max() - origin).cast<float>();
  const double max_extent = (hi - lo).cast<double>().maxCoeff();
  constexpr double kMaxCells = (1 << 21) - 2;
  if (max_extent / cell > kMaxCells) cell = max_extent / kMaxCells * (1 + 1e-6);
  g.lo = lo - Eigen::Vector3f::Constant(static_cast<float>(cell) * 0.5f);
  g.inv_cell = static_cast<float>(1.0 / cell);
  for (int a = 0; a < 3; ++a)
    g.dims[a] = std::min<std::int32_t>(
        static_cast<std::int32_t>(std::floor((hi[a] - g.lo[a]) * g.inv_cell)) + 2, (1 << 21) - 1);
  return g;
}

// Record numbers in the scratch files carry the kernel-site mark in their top bit.
constexpr std::uint64_t kSiteBit = std::uint64_t{1} << 63;

struct Plan {
  Grid grid;
  std::vector<TilePlanEntry> tiles;
  std::vector<std::array<std::int64_t, 6>>
      cells;  // per tile: lo xyz, hi xyz (cell indices, hi excl.)
  std::vector<std::uint32_t> tile_of_cell;
  std::int64_t halo_cells = 1;
};

class Prefix {
 public:
  Prefix(const Grid& g, const std::vector<std::uint64_t>& h) : d_(g.dims) {
    const std::int64_t X = d_[0] + 1, Y = d_[1] + 1, Z = d_[2] + 1;
    s_.assign(static_cast<std::size_t>(X * Y * Z), 0);
    for (std::int64_t z = 1; z < Z; ++z)
      for (std::int64_t y = 1; y < Y; ++y)
        for (std::int64_t x = 1; x < X; ++x)
          s_[at(x, y, z)] = h[g.flat({x - 1, y - 1, z - 1})] + s_[at(x - 1, y, z)] +
                            s_[at(x, y - 1, z)] + s_[at(x, y, z - 1)] - s_[at(x - 1, y - 1, z)] -
                            s_[at(x - 1, y, z - 1)] - s_[at(x, y - 1, z - 1)] +
                            s_[at(x - 1, y - 1, z - 1)];
  }
  // Points in cells [lo, hi) (clipped to the grid).
  std::uint64_t count(std::array<std::int64_t, 6> b) const {
    for (int a = 0; a < 3; ++a) {
      b[a] = std::clamp<std::int64_t>(b[a], 0, d_[a]);
      b[a + 3] = std::clamp<std::int64_t>(b[a + 3], 0, d_[a]);
      if (b[a + 3] <= b[a]) return 0;
    }
    const auto [x0, y0, z0, x1, y1, z1] = b;
    return s_[at(x1, y1, z1)] - s_[at(x0, y1, z1)] - s_[at(x1, y0, z1)] - s_[at(x1, y1, z0)] +
           s_[at(x0, y0, z1)] + s_[at(x0, y1, z0)] + s_[at(x1, y0, z0)] - s_[at(x0, y0, z0)];
  }

 private:
  std::size_t at(std::int64_t x, std::int64_t y, std::int64_t z) const {
    return static_cast<std::size_t>((z * (d_[1] + 1) + y) * (d_[0] + 1) + x);
  }
  std::array<std::int64_t, 3> d_;
  std::vector<std::uint64_t> s_;
};

Plan make_plan(const Grid& grid, const std::vector<std::uint64_t>& hist, double halo,
               std::uint64_t limit, int ranks) {
  Plan plan;
  plan.grid = grid;
  plan.halo_cells =
      std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(halo / grid.cell)));
  const Prefix prefix(grid, hist);
  auto grown = [&](std::array<std::int64_t, 6> b) {
    for (int a = 0; a < 3; ++a) {
      b[a] -= plan.halo_cells;
      b[a + 3] += plan.halo_cells;
    }
    return b;
  };
  // Recursive bisection, depth first: leaves in order are the tiles.
  std::vector<std::array<std::int64_t, 6>> stack{
      {0, 0, 0, grid.dims[0], grid.dims[1], grid.dims[2]}};
  while (!stack.empty()) {
    const auto b = stack.back();
    stack.pop_back();
    const std::uint64_t own = prefix.count(b);
    if (own == 0) continue;
    const std::uint64_t with_halo = prefix.count(grown(b));
    if (with_halo <= limit) {
      plan.cells.push_back(b);
      continue;
    }
    // The cut (any axis, at least one cell on each side) whose larger half, halo included,
    // holds the fewest points; none that helps (the halo dominates): the box stays one tile.
    int axis = -1;
    std::int64_t cut = 0;
    std::uint64_t best = with_halo - with_halo / 16;
    for (int a = 0; a < 3; ++a)
      for (std::int64_t c = b[a] + 1; c < b[a + 3]; ++c) {
        auto l = b, r = b;
        l[a + 3] = c;
        r[a] = c;
        const std::uint64_t worst = std::max(prefix.count(grown(l)), prefix.count(grown(r)));
        if (worst < best) {
          best = worst;
          axis = a;
          cut = c;
        }
      }
    if (axis < 0) {
      plan.cells.push_back(b);
      continue;
    }
    auto left = b, right = b;
    left[axis + 3] = cut;
    right[axis] = cut;
    stack.push_back(right);  // the left half is handled first
    stack.push_back(left);
  }
  plan.tile_of_cell.assign(grid.cells(), 0);
  std::vector<std::uint64_t> load(static_cast<std::size_t>(std::max(1, ranks)), 0);
  for (std::size_t t = 0; t < plan.cells.size(); ++t) {
    const auto& b = plan.cells[t];
    TilePlanEntry e;
    e.box = Eigen::AlignedBox3d(grid.lo + grid.cell * Eigen::Vector3d(b[0], b[1], b[2]),
                                grid.lo + grid.cell * Eigen::Vector3d(b[3], b[4], b[5]));
    e.own_points = prefix.count(b);
    e.with_halo = prefix.count(grown(b));
    for (std::int64_t z = b[2]; z < b[5]; ++z)
      for (std::int64_t y = b[1]; y < b[4]; ++y)
        for (std::int64_t x = b[0]; x < b[3]; ++x)
          plan.tile_of_cell[grid.flat({x, y, z})] = static_cast<std::uint32_t>(t);
    plan.tiles.push_back(e);
  }
  // Ranks: the largest tiles first, each to the least loaded rank (deterministic).
  std::vector<std::size_t> by_size(plan.tiles.size());
  std::iota(by_size.begin(), by_size.end(), 0);
  std::stable_sort(by_size.begin(), by_size.end(), [&](std::size_t a, std::size_t b) {
    return plan.tiles[a].with_halo > plan.tiles[b].with_halo;
  });
  for (std::size_t t : by_size) {
    const auto r =
        static_cast<std::size_t>(std::min_element(load.begin(), load.end()) - load.begin());
    plan.tiles[t].rank = static_cast<int>(r);
    load[r] += plan.tiles[t].with_halo;
  }
  return plan;
}

// ---- scratch records: one point of a tile ----

struct Columns {
  bool normals = false, confidences = false, intensities = false, colors = false;
  //! The input's attributes (TiledSource::attributes), each value a double in the record.
  std::vector<std::pair<std::string, AttributeType>> attributes;
  std::size_t bytes() const {
    return 8 + 24 + (normals ? 12 : 0) + (confidences ? 4 : 0) + (intensities ? 4 : 0) +
           (colors ? 4 : 0) + 8 * attributes.size();
  }
};

void put_point(std::string& buf, const PointCloud& c, std::size_t i, std::uint64_t record,
               const Columns& cols) {
  auto put = [&](const void* p, std::size_t n) { buf.append(static_cast<const char*>(p), n); };
  put(&record, 8);
  put(c.positions[i].data(), 24);
  if (cols.normals) put(c.normals[i].data(), 12);
  if (cols.confidences) put(&c.confidences[i], 4);
  if (cols.intensities) put(&c.intensities[i], 4);
  if (cols.colors) put(c.colors[i].data(), 4);
  for (const Attribute& a : c.attributes) put(&a.values[i], 8);
}

void read_points(const std::filesystem::path& file, const Columns& cols, PointCloud& c,
                 std::vector<std::uint64_t>& records) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return;  // no point of this rank's range fell into the tile
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  const std::size_t n = bytes.size() / cols.bytes();
  if (n * cols.bytes() != bytes.size())
    throw IoError(file.string() + ": scratch file of a tile has a partial record");
  const char* p = bytes.data();
  if (c.attributes.empty())
    for (const auto& [name, type] : cols.attributes) c.attributes.push_back({name, type, {}});
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t rec;
    std::memcpy(&rec, p, 8);
    records.push_back(rec);
    Eigen::Vector3d x;
    std::memcpy(x.data(), p + 8, 24);
    c.positions.push_back(x);
    p += 32;
    if (cols.normals) {
      Eigen::Vector3f v;
      std::memcpy(v.data(), p, 12);
      c.normals.push_back(v);
      p += 12;
    }
    auto f32 = [&](std::vector<float>& v) {
      float f;
      std::memcpy(&f, p, 4);
      v.push_back(f);
      p += 4;
    };
    if (cols.confidences) f32(c.confidences);
    if (cols.intensities) f32(c.intensities);
    if (cols.colors) {
      std::array<std::uint8_t, 4> col;
      std::memcpy(col.data(), p, 4);
      c.colors.push_back(col);
      p += 4;
    }
    for (Attribute& a : c.attributes) {
      double v;
      std::memcpy(&v, p, 8);
      a.values.push_back(v);
      p += 8;
    }
  }
}

std::filesystem::path scratch_file(const TiledOptions& t, std::size_t tile, int rank) {
  char name[64];
  std::snprintf(name, sizeof name, "tile%06zu.r%04d.pts", tile, rank);
  return t.scratch / name;
}

// robust_filter's input checks (input_checks.h), made in the first pass so that the error names
// the record, before a grid casts a coordinate to a cell and before any tile reaches the sink.
void check_chunk(const PointCloud& c, const std::vector<std::uint64_t>& rec,
                 const FilterOptions& o) {
  const bool weights = o.use_confidences && c.has_confidences();
  if (weights && c.confidences.size() != c.size())
    throw InputError("tiled filter input",
                     rec.empty() ? "a chunk" : "the chunk from record " + std::to_string(rec[0]),
                     "one confidence per point");
  const detail::InvalidPoint bad = detail::first_invalid_point(c, weights);
  if (bad.index < c.size())
    throw InputError("tiled filter input", "record " + std::to_string(rec[bad.index]), bad.what);
}

// Removes the scratch files when the run ends by an exception (a run that ends normally has
// removed each as its tile read it). With one process, its own. With several, every process's:
// the others wait for this one in their next exchange, so the run is over for all of them, and
// a process stopped there (MPI_Abort) cannot clean up after itself.
class ScratchCleanup {
 public:
  ScratchCleanup(const TiledOptions& t, const Plan& plan, int ranks)
      : t_(t), plan_(plan), ranks_(std::max(1, ranks)) {}
  ScratchCleanup(const ScratchCleanup&) = delete;
  ScratchCleanup& operator=(const ScratchCleanup&) = delete;
  ~ScratchCleanup() {
    if (std::uncaught_exceptions() == uncaught_) return;
    for (std::size_t k = 0; k < plan_.tiles.size(); ++k)
      for (int r = 0; r < ranks_; ++r) {
        std::error_code ec;
        std::filesystem::remove(scratch_file(t_, k, r), ec);
      }
  }

 private:
  const TiledOptions& t_;
  const Plan& plan_;
  int ranks_;
  int uncaught_ = std::uncaught_exceptions();
};

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
  TiledGlobals& gl = st.globals;
  const auto [rb, re] = my_range(src.records, comm);
  // Named for the lambdas below: clang before 16 cannot capture a structured binding.
  const std::uint64_t my_records = re - rb + 1;
  const std::size_t chunk = t.chunk_records;
  const int K = o.scale == ScaleMode::kAdaptive ? o.k_adaptive : o.k_h;

  // Pass 1: box, count, arrays present, the sample of the automatic h.
  progress("first pass", 0);
  const std::uint64_t M = std::min<std::uint64_t>(src.records, 10000);
  std::vector<std::uint64_t> sample_rec(M);
  for (std::uint64_t k = 0; k < M; ++k) sample_rec[k] = k * src.records / M;
  Columns cols;
  cols.attributes = src.attributes;
  std::vector<Eigen::Vector3d> sample_xyz;  // the samples' positions, in record order
  {
    Eigen::AlignedBox3d box;
    std::uint64_t n = 0;
    std::uint8_t has[4] = {0, 0, 0, 0};
    Bytes samples;
    std::size_t next = static_cast<std::size_t>(
        std::lower_bound(sample_rec.begin(), sample_rec.end(), rb) - sample_rec.begin());
    stream(src, rb, re, chunk, [&](const PointCloud& c, const std::vector<std::uint64_t>& rec) {
      if (c.attributes.size() != cols.attributes.size())
        throw std::logic_error("tiled filter: read() gave other attributes than announced");
      check_chunk(c, rec, o);
      for (const auto& p : c.positions) box.extend(p);
      n += c.size();
      has[0] |= c.has_normals();
      has[1] |= c.has_confidences();
      has[2] |= c.has_intensities();
      has[3] |= c.has_colors();
      for (std::size_t i = 0; i < c.size(); ++i) {
        while (next < sample_rec.size() && sample_rec[next] < rec[i]) ++next;
        if (next < sample_rec.size() && sample_rec[next] == rec[i]) {
          samples.put<std::uint64_t>(rec[i]);
          samples.put(c.positions[i]);
          samples.put(c.has_normals() ? c.normals[i] : Eigen::Vector3f::Zero().eval());
          samples.put<float>(c.has_confidences() ? c.confidences[i] : 1.0f);
        }
      }
    });
    Bytes mine;
    mine.put(box.min());
    mine.put(box.max());
    mine.put<std::uint64_t>(n);
    mine.s.append(reinterpret_cast<const char*>(has), 4);
    mine.put_vec(std::vector<char>(samples.s.begin(), samples.s.end()));
    std::vector<std::uint64_t> valid_samples;
    std::vector<Eigen::Vector3d> sample_pos;
    for (const std::string& m : allgather(comm, mine.s)) {
      Reader r{m};
      const auto lo = r.get<Eigen::Vector3d>(), hi = r.get<Eigen::Vector3d>();
      if ((lo.array() <= hi.array()).all()) {
        gl.box.extend(lo);
        gl.box.extend(hi);
      }
      gl.points += r.get<std::uint64_t>();
      const auto h4 = r.get<std::array<std::uint8_t, 4>>();
      cols.normals |= h4[0] != 0;
      cols.confidences |= h4[1] != 0;
      cols.intensities |= h4[2] != 0;
      cols.colors |= h4[3] != 0;
      const std::vector<char> sv = r.get_vec<char>();
      const std::string ss(sv.begin(), sv.end());
      Reader s{ss};
      while (!s.done()) {
        valid_samples.push_back(s.get<std::uint64_t>());
        sample_pos.push_back(s.get<Eigen::Vector3d>());
        s.get<Eigen::Vector3f>();
        s.get<float>();
      }
    }
    sample_rec = valid_samples;  // in record order (ranks read ascending ranges)
    sample_xyz = std::move(sample_pos);
  }
  st.points_in = gl.points;
  if (gl.points == 0) return st;
  const bool use_w = o.use_confidences && cols.confidences;
  const bool use_v = o.use_sensor_normals && cols.normals;
  const Eigen::Vector3d origin = gl.box.center();
  const double diag = gl.box.diagonal().norm();
  const double fallback_h = diag > 0 ? 1e-3 * diag : 1e-3;
  const Grid grid = make_grid(gl.box);
  std::vector<std::uint64_t> hist(grid.cells(), 0);

  // Pass 2: the histogram, and the K-th neighbour distances of the samples (kAuto, kAdaptive).
  std::vector<Eigen::Vector3f> qf;  // the samples, float, relative to the origin
  for (const Eigen::Vector3d& p : sample_xyz) qf.push_back((p - origin).cast<float>());
  std::vector<double> kth(qf.size(), 0.0);
  double reach = 0;
  if (o.scale != ScaleMode::kFixed && !qf.empty()) {
    // A first reach from the samples' own spacing: the 8th neighbour among the samples, scaled
    // to K neighbours among all points as on a surface; grown until every sample has K + 1.
    {
      NeighborIndex sidx(qf, 0.0);
      std::vector<double> d8(qf.size());
      for (std::size_t k = 0; k < qf.size(); ++k) {
        std::vector<std::pair<float, std::uint32_t>> nn;
        sidx.knn(qf[k], 9, nn);
        d8[k] = nn.empty() ? 0.0 : std::sqrt(static_cast<double>(nn.back().first));
      }
      const double r8 = detail::median_of(d8);
      reach = r8 *
              std::sqrt(static_cast<double>(K + 1) * static_cast<double>(qf.size()) /
                        (8.0 * static_cast<double>(gl.points))) *
              2.0;
      if (!(reach > 0)) reach = fallback_h;
    }
  }
  // Each pass takes the samples still short of K + 1 neighbours (sparse clutter) with a reach
  // three times the last one's; the others keep their distances.
  // kAuto also takes scale.h's rough estimate r_est, which sizes the in-memory run's first point
  // index (and so, when it is kept for the kernels, their grid order): the median distance of
  // the samples to their ks-th nearest among every sub_step-th point.
  const bool want_est = o.scale == ScaleMode::kAuto;
  const std::uint64_t kk = static_cast<std::uint64_t>(K) + 1;
  const std::uint64_t sub_step = std::clamp<std::uint64_t>(gl.points / (8 * kk), 1, 16);
  const std::size_t ks =
      static_cast<std::size_t>(std::max<std::uint64_t>(2, (kk + sub_step / 2) / sub_step));
  std::vector<double> est(want_est ? qf.size() : 0, -1.0);
  std::vector<std::uint8_t> kth_done(qf.size(), 0);
  bool hist_done = false;
  std::vector<std::uint32_t> active(o.scale != ScaleMode::kFixed ? qf.size() : 0);
  std::iota(active.begin(), active.end(), 0u);
  while (true) {
    const bool need_kth = !active.empty();
    if (hist_done && !need_kth) break;
    std::vector<std::vector<float>> d2(active.size()), d2s(want_est ? active.size() : 0);
    const float R = static_cast<float>(reach);
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> near;  // cell -> active slot
    auto key = [&](const Eigen::Vector3f& p, int dx, int dy, int dz) {
      const auto c = [&](int a, int d) {
        return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(p[a] / R)) + d +
                                          (1 << 20)) &
               0x1fffff;
      };
      return c(0, dx) | (c(1, dy) << 21) | (c(2, dz) << 42);
    };
    // Each sample is listed in the 27 cells around its own: a point looks up its cell only.
    for (std::size_t k = 0; k < active.size(); ++k)
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            near[key(qf[active[k]], dx, dy, dz)].push_back(static_cast<std::uint32_t>(k));
    stream(src, rb, re, chunk, [&](const PointCloud& c, const std::vector<std::uint64_t>& rec) {
      for (std::size_t i = 0; i < c.size(); ++i) {
        const Eigen::Vector3d& p = c.positions[i];
        if (!hist_done) ++hist[grid.flat(grid.cell_of(p))];
        if (!need_kth) continue;
        const Eigen::Vector3f pf = (p - origin).cast<float>();
        const auto it = near.find(key(pf, 0, 0, 0));
        if (it == near.end()) continue;
        for (std::uint32_t k : it->second) {
          // The same float arithmetic as the neighbour index's distance test.
          const Eigen::Vector3f& q = qf[active[k]];
          const float ex = pf.x() - q.x(), ey = pf.y() - q.y(), ez = pf.z() - q.z();
          const float dd = ex * ex + ey * ey + ez * ez;
          if (!(dd < R * R)) continue;
          d2[k].push_back(dd);
          if (want_est && rec[i] % sub_step == 0) d2s[k].push_back(dd);
        }
      }
    });
    // Sum the histograms and join the distance lists of every process.
    if (comm.ranks > 1) {
      Bytes mine;
      if (!hist_done) mine.put_vec(hist);
      for (auto& v : d2) mine.put_vec(v);
      for (auto& v : d2s) mine.put_vec(v);
      std::vector<std::uint64_t> sum(hist_done ? 0 : hist.size(), 0);
      std::vector<std::vector<float>> joined(d2.size()), joined_s(d2s.size());
      for (const std::string& m : allgather(comm, mine.s)) {
        Reader r{m};
        if (!hist_done) {
          const auto h = r.get_vec<std::uint64_t>();
          for (std::size_t i = 0; i < h.size(); ++i) sum[i] += h[i];
        }
        for (auto* all : {&joined, &joined_s})
          for (auto& v : *all) {
            const auto part = r.get_vec<float>();
            v.insert(v.end(), part.begin(), part.end());
          }
      }
      if (!hist_done) hist = std::move(sum);
      d2 = std::move(joined);
      d2s = std::move(joined_s);
    }
    hist_done = true;
    const bool all_within = reach >= 2 * diag + fallback_h;
    std::vector<std::uint32_t> still;
    for (std::size_t k = 0; k < active.size(); ++k) {
      const std::uint32_t a = active[k];
      if (!kth_done[a]) {
        kth[a] = detail::kth_distance(d2[k], K, R, all_within);
        kth_done[a] = kth[a] >= 0;
      }
      if (want_est && est[a] < 0) {
        // As a k-d tree's ks nearest: the ks-th smallest distance, or the largest when fewer.
        auto& v = d2s[k];
        if (v.size() >= ks)
          est[a] = std::sqrt(
              static_cast<double>(detail::kth_smallest_below(v.data(), v.size(), ks - 1, R * R)));
        else if (all_within)
          est[a] = v.empty()
                       ? 0.0
                       : std::sqrt(static_cast<double>(*std::max_element(v.begin(), v.end())));
      }
      if (!kth_done[a] || (want_est && est[a] < 0)) still.push_back(a);
    }
    active = std::move(still);
    reach = std::min(reach * 3.0, 2 * diag + fallback_h);
  }
  gl.h0 = 0;
  if (o.scale == ScaleMode::kFixed) {
    gl.h = o.h;
  } else {
    const double med = detail::median_of(kth);
    gl.h0 = med > 0 ? med : fallback_h;
    gl.h = gl.h0;
  }

  // Pass 3 (kAuto): the neighbourhoods of every 4th sample: noise and the scale test.
  if (o.scale == ScaleMode::kAuto) {
    const std::size_t step = M >= 4000 ? 4 : 1;
    std::vector<std::size_t> qs;  // indices into qf
    for (std::size_t k = 0; k < qf.size(); k += step) qs.push_back(k);
    double R = 3.0 * gl.h0;
    for (int attempt = 0; attempt < 6; ++attempt) {
      const float Rf = static_cast<float>(R);
      std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> near;
      auto key = [&](const Eigen::Vector3f& p, int dx, int dy, int dz) {
        const auto c = [&](int a, int d) {
          return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(p[a] / Rf)) + d +
                                            (1 << 20)) &
                 0x1fffff;
        };
        return c(0, dx) | (c(1, dy) << 21) | (c(2, dz) << 42);
      };
      for (std::size_t k : qs)
        for (int dz = -1; dz <= 1; ++dz)
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx)
              near[key(qf[k], dx, dy, dz)].push_back(static_cast<std::uint32_t>(k));
      Bytes mine;
      std::uint64_t count = 0;
      stream(src, rb, re, chunk, [&](const PointCloud& c, const std::vector<std::uint64_t>&) {
        for (std::size_t i = 0; i < c.size(); ++i) {
          const Eigen::Vector3f pf = (c.positions[i] - origin).cast<float>();
          const auto it = near.find(key(pf, 0, 0, 0));
          if (it == near.end()) continue;
          bool hit = false;
          for (std::uint32_t s : it->second)
            if ((pf - qf[s]).squaredNorm() < Rf * Rf * 1.0001f) {
              hit = true;
              break;
            }
          if (!hit) continue;
          ++count;
          mine.put(c.positions[i]);
          mine.put(c.has_normals() ? c.normals[i] : Eigen::Vector3f::Zero().eval());
          mine.put<float>(c.has_confidences() ? c.confidences[i] : 1.0f);
        }
      });
      detail::PointSet g;
      g.v_orients_only = o.normals_orient_only;
      for (const std::string& m : allgather(comm, mine.s)) {
        Reader r{m};
        while (!r.done()) {
          g.p.push_back(r.get<Eigen::Vector3d>() - origin);
          const auto v = r.get<Eigen::Vector3f>();
          const float w = r.get<float>();
          if (use_v) {
            const float len = v.norm();
            g.v.push_back((std::isfinite(len) && len > 1e-6f) ? Eigen::Vector3f(v / len)
                                                              : Eigen::Vector3f::Zero());
          }
          if (use_w) g.w.push_back(w);
        }
      }
      // The samples among the gathered points (each sample is there: its own distance is 0).
      std::vector<Eigen::Vector3f> gf(g.p.size());
      for (std::size_t i = 0; i < g.p.size(); ++i) gf[i] = g.p[i].cast<float>();
      std::vector<std::size_t> in_g;
      {
        NeighborIndex gi(gf, std::max(1e-9, gl.h0));
        for (std::size_t k : qs) {
          std::vector<std::pair<float, std::uint32_t>> nn;
          gi.knn(qf[k], 1, nn);
          in_g.push_back(nn.empty() ? 0 : nn[0].second);
        }
      }
      // As scale.h: the noise over the first M / step of them, the scale test over all.
      const std::vector<std::size_t> in_g_sigma(
          in_g.begin(), in_g.begin() + static_cast<std::ptrdiff_t>(qf.size() / step));
      const detail::TileScale ts =
          detail::scale_from_neighbourhoods(g, in_g_sigma, in_g, gl.h0, diag, use_v, o);
      if (ts.reach <= R || R >= 2 * diag + fallback_h) {
        gl.h = ts.h;
        gl.noise_sigma = ts.noise_sigma;
        gl.noise_sigma_h0 = ts.noise_sigma_h0;
        gl.h_noise = ts.h_noise;
        break;
      }
      R = std::min(ts.reach * 1.25, 2 * diag + fallback_h);
    }
  }
  gl.mean_spacing =
      (o.scale == ScaleMode::kAuto ? gl.h0 : gl.h) / std::sqrt(static_cast<double>(K) / M_PI);
  gl.merge_eps = o.merge_eps < 0 ? 0.25 * gl.mean_spacing : o.merge_eps;
  if (o.kernel_stride > 0)
    gl.kernel_stride = o.kernel_stride;
  else if (o.scale == ScaleMode::kAuto && gl.h0 > 0)
    gl.kernel_stride =
        static_cast<int>(std::clamp(std::floor((gl.h / gl.h0) * (gl.h / gl.h0)), 1.0, 64.0));
  else if (o.scale == ScaleMode::kAdaptive)
    gl.kernel_stride = std::clamp(o.k_adaptive / o.k_h, 1, 64);
  gl.min_component_size =
      o.min_component_size > 0
          ? o.min_component_size
          : std::max<std::size_t>(
                static_cast<std::size_t>(o.k_min),
                static_cast<std::size_t>(std::ceil(1e-3 * static_cast<double>(gl.points))));
  // kAdaptive: the halo from a high percentile of the sampled h_i (the largest support).
  double h_reach = gl.h;
  if (o.scale == ScaleMode::kAdaptive && !kth.empty()) {
    std::vector<double> s = kth;
    std::sort(s.begin(), s.end());
    h_reach = s[s.size() * 95 / 100];
  }
  gl.halo = t.halo_factor * h_reach;
  st.seconds_globals = seconds_since(t_start);
  if (t.on_globals) t.on_globals(gl);

  // The tile plan; pass 4 (kernel stride > 1): the kernel sites; pass 5: every point into the
  // scratch files of its tiles.
  auto t_dist = Clock::now();
  const Plan plan =
      make_plan(grid, hist, gl.halo,
                t.max_tile_points > 0 ? t.max_tile_points
                                      : tile_point_limit(t.memory_budget, cols.attributes.size()),
                comm.ranks);
  std::vector<std::uint64_t>().swap(hist);
  st.tiles = plan.tiles.size();
  // Kernels at every stride-th point of the whole cloud's grid order (kernels.h), not of each
  // tile's: per cell of the in-memory run's point index, the points in the cells before it in
  // Morton order (mod stride), and in it those of the lower ranks' records; the distribution
  // pass then numbers the points of each cell in record order, the index's order within a cell.
  // The cell of the in-memory run's kernel-phase point index (scale.h, robust_filter.cpp): the
  // scale phase's index (cell 1.6 r_est, else 1.001 h0) when its cell lies in [1.001 h, 1.7 h],
  // else a new one of cell 1.001 h.
  double site_cell = grid_cell_for(gl.h);
  if (want_est) {
    double r_est = detail::median_of(est);
    if (!(r_est > 0)) r_est = fallback_h;
    double c1 = r_est * 1.6;
    if (!grid_serves(c1, gl.h0)) c1 = grid_cell_for(gl.h0);
    if (grid_serves(c1, gl.h)) site_cell = c1;
  }
  const std::uint64_t stride = static_cast<std::uint64_t>(std::max(1, gl.kernel_stride));
  const bool want_sites = stride > 1 && o.scale != ScaleMode::kAdaptive;
  SiteGrid sg;
  // Per occupied cell: {points in it, of which in lower ranks' records} while counting, then
  // {rank of its first point mod stride (this process's records), points numbered so far}.
  std::unordered_map<std::uint64_t, std::array<std::uint64_t, 2>> site_cells;
  if (want_sites) {
    progress("kernel sites", 0);
    sg = site_grid(gl.box, origin, site_cell);
    std::unordered_map<std::uint64_t, std::uint64_t> counts;
    stream(src, rb, re, chunk, [&](const PointCloud& c, const std::vector<std::uint64_t>&) {
      for (const auto& p : c.positions) ++counts[sg.code((p - origin).cast<float>())];
    });
    std::vector<std::array<std::uint64_t, 2>> mine;  // code, count
    mine.reserve(counts.size());
    for (const auto& [code, n] : counts) mine.push_back({code, n});
    std::unordered_map<std::uint64_t, std::uint64_t>().swap(counts);
    Bytes msg;
    msg.put_vec(mine);
    std::vector<std::array<std::uint64_t, 2>>().swap(mine);
    std::vector<std::string> all = allgather(comm, msg.s);
    std::string().swap(msg.s);
    for (std::size_t r = 0; r < all.size(); ++r) {
      Reader rd{all[r]};
      for (const auto& [code, n] : rd.get_vec<std::array<std::uint64_t, 2>>()) {
        auto& e = site_cells[code];
        e[0] += n;
        if (static_cast<int>(r) < comm.rank) e[1] += n;
      }
      std::string().swap(all[r]);
    }
    std::vector<std::uint64_t> codes;
    codes.reserve(site_cells.size());
    for (const auto& kv : site_cells) codes.push_back(kv.first);
    std::sort(codes.begin(), codes.end());
    std::uint64_t before = 0;
    for (std::uint64_t code : codes) {
      auto& e = site_cells[code];
      const std::uint64_t n = e[0];
      e = {(before + e[1]) % stride, 0};
      before += n;
    }
  }
  progress("distributing", 0);
  const ScratchCleanup cleanup(t, plan, comm.ranks);
  {
    const std::size_t T = plan.tiles.size();
    const std::size_t flush_at = std::clamp<std::size_t>(
        t.memory_budget / 16 / std::max<std::size_t>(1, T), 4096, std::size_t{1} << 20);
    std::vector<std::string> buf(T);
    std::vector<std::unique_ptr<std::ofstream>> files(T);
    auto flush = [&](std::size_t k) {
      if (buf[k].empty()) return;
      if (!files[k]) {
        files[k] = std::make_unique<std::ofstream>(scratch_file(t, k, comm.rank),
                                                   std::ios::binary | std::ios::trunc);
        if (!*files[k])
          throw IoError(scratch_file(t, k, comm.rank).string() + ": cannot create a scratch file");
      }
      files[k]->write(buf[k].data(), static_cast<std::streamsize>(buf[k].size()));
      if (!*files[k])
        throw IoError(scratch_file(t, k, comm.rank).string() + ": write failed (disk full?)");
      buf[k].clear();
    };
    // A coarse lookup grid (cells of at least the halo): per cell, the tiles whose box grown by
    // the halo meets it; a point tests only those.
    Grid look;
    look.lo = grid.lo;
    {
      const Eigen::Vector3d ext = gl.box.diagonal().cwiseMax(0.0);
      look.cell = std::max({gl.halo, ext.maxCoeff() / 128.0, 1e-12});
      for (int a = 0; a < 3; ++a)
        look.dims[a] =
            std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(ext[a] / look.cell)));
    }
    std::vector<std::vector<std::uint32_t>> look_tiles(look.cells());
    for (std::size_t k = 0; k < T; ++k) {
      const auto& b = plan.tiles[k].box;
      const Eigen::Vector3d h3 = Eigen::Vector3d::Constant(gl.halo);
      const auto lo = look.cell_of(b.min() - h3), hi = look.cell_of(b.max() + h3);
      for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
          for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
            look_tiles[look.flat({x, y, z})].push_back(static_cast<std::uint32_t>(k));
    }
    std::vector<std::uint32_t> hits;
    std::uint64_t done = 0;
    stream(src, rb, re, chunk, [&](const PointCloud& c, const std::vector<std::uint64_t>& rec) {
      for (std::size_t i = 0; i < c.size(); ++i) {
        const Eigen::Vector3d& p = c.positions[i];
        const std::uint32_t home = plan.tile_of_cell[grid.flat(grid.cell_of(p))];
        hits.assign(1, home);
        for (std::uint32_t k : look_tiles[look.flat(look.cell_of(p))]) {
          if (k == home) continue;
          // Within the halo of the tile's box.
          const auto& b = plan.tiles[k].box;
          const Eigen::Vector3d gap =
              (b.min() - p).cwiseMax(p - b.max()).cwiseMax(Eigen::Vector3d::Zero());
          if (gap.maxCoeff() <= gl.halo) hits.push_back(k);
        }
        std::uint64_t tagged = rec[i];
        if (want_sites) {
          auto& e = site_cells[sg.code((p - origin).cast<float>())];
          if ((e[0] + e[1]++) % stride == 0) tagged |= kSiteBit;
        }
        for (std::uint32_t k : hits) {
          put_point(buf[k], c, i, tagged, cols);
          if (buf[k].size() >= flush_at) flush(k);
        }
      }
      done += c.size();
      progress("distributing", static_cast<double>(done) / static_cast<double>(my_records));
    });
    for (std::size_t k = 0; k < T; ++k) flush(k);
    for (auto& f : files)
      if (f) {
        f->close();
        if (!*f) throw IoError("a scratch file of the tiled filter could not be closed");
      }
  }
  allgather(comm, {});  // every process's scratch files are complete
  st.seconds_distribute = seconds_since(t_dist);

  decltype(site_cells)().swap(site_cells);

  // Pass 6: the tiles of this process, in tile order.
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
  std::size_t mine_total = 0, mine_done = 0;
  for (const auto& e : plan.tiles) mine_total += e.rank == comm.rank ? 1 : 0;
  for (std::size_t k = 0; k < plan.tiles.size(); ++k) {
    if (plan.tiles[k].rank != comm.rank) continue;
    PointCloud c;
    std::vector<std::uint64_t> rec;
    for (int r = 0; r < std::max(1, comm.ranks); ++r) {
      read_points(scratch_file(t, k, r), cols, c, rec);
      std::error_code ec;
      std::filesystem::remove(scratch_file(t, k, r), ec);
    }
    if (want_sites) {
      std::vector<double> site(rec.size());
      for (std::size_t i = 0; i < rec.size(); ++i) {
        site[i] = (rec[i] & kSiteBit) ? 1.0 : 0.0;
        rec[i] &= ~kSiteBit;
      }
      c.set_attribute(detail::kKernelSitesAttribute, AttributeType::kUInt8, std::move(site));
    }
    std::vector<std::uint8_t> own(c.size(), 0);
    std::uint64_t own_n = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
      own[i] = plan.tile_of_cell[grid.flat(grid.cell_of(c.positions[i]))] == k ? 1 : 0;
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
    progress("tiles", static_cast<double>(++mine_done) /
                          static_cast<double>(std::max<std::size_t>(1, mine_total)));
  }
  st.seconds_tiles = seconds_since(t_tiles);
  // Totals over every process.
  {
    Bytes mine;
    for (std::uint64_t v : {st.points_out, st.outliers, st.unsupported, st.merged})
      mine.put<std::uint64_t>(v);
    if (comm.ranks > 1) {
      std::uint64_t sums[4] = {0, 0, 0, 0};
      for (const std::string& m : allgather(comm, mine.s)) {
        Reader r{m};
        for (auto& s : sums) s += r.get<std::uint64_t>();
      }
      st.points_out = sums[0];
      st.outliers = sums[1];
      st.unsupported = sums[2];
      st.merged = sums[3];
    }
  }
  st.seconds_total = seconds_since(t_start);
  st.peak_rss_bytes = peak_rss();
  return st;
}

}  // namespace scanclean
