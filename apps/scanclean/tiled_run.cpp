// Needs the io and filter modules (as cmd_filter.cpp).
#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_FILTER)

#include "scanclean/tiled_run.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/ply_stream_writer.h"
#include "scanclean/io/point_stream.h"
#include "scanclean/provenance.h"

namespace scanclean::app {

std::size_t parse_memory_size(const std::string& option, const std::string& text) {
  std::size_t used = 0;
  double v = -1;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  std::string unit = text.substr(used);
  if (!unit.empty() && (unit.back() == 'B' || unit.back() == 'b')) unit.pop_back();
  if (!unit.empty() && (unit.back() == 'i')) unit.pop_back();
  double scale = 1;
  if (unit == "K" || unit == "k")
    scale = 1024.0;
  else if (unit == "M" || unit == "m")
    scale = 1024.0 * 1024;
  else if (unit == "G" || unit == "g")
    scale = 1024.0 * 1024 * 1024;
  else if (unit == "T" || unit == "t")
    scale = 1024.0 * 1024 * 1024 * 1024;
  else if (!unit.empty())
    used = 0;
  if (used == 0 || !(v >= 0) || !std::isfinite(v * scale))
    throw OptionError(option + ": expected a size such as 2G, 1536M or 800000000 (bytes), got \"" +
                      text + "\"");
  return static_cast<std::size_t>(v * scale);
}

std::size_t default_memory_budget() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  const std::size_t two = std::size_t{2} << 30;
  if (pages <= 0 || page <= 0) return two;
  const std::size_t half = static_cast<std::size_t>(pages) * static_cast<std::size_t>(page) / 2;
  return std::max<std::size_t>(std::size_t{256} << 20, std::min(two, half));
}

namespace {

// One tile's encoded result in the scratch folder (several processes).
std::filesystem::path part_file(const std::filesystem::path& scratch, std::size_t tile) {
  char name[48];
  std::snprintf(name, sizeof name, "out%06zu.part", tile);
  return scratch / name;
}

// A name part_file() gives: "out", digits, ".part".
bool is_part_file(const std::filesystem::path& p) {
  const std::string n = p.filename().string();
  return n.size() > 8 && n.starts_with("out") && n.ends_with(".part") &&
         std::all_of(n.begin() + 3, n.end() - 5, [](char ch) { return ch >= '0' && ch <= '9'; });
}

void put_block(std::ostream& os, std::uint64_t points, const std::string& bytes) {
  const std::uint64_t size = bytes.size();
  os.write(reinterpret_cast<const char*>(&points), 8);
  os.write(reinterpret_cast<const char*>(&size), 8);
  os.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

std::pair<std::uint64_t, std::string> get_block(std::istream& is, const std::filesystem::path& f) {
  std::uint64_t points = 0, size = 0;
  is.read(reinterpret_cast<char*>(&points), 8);
  is.read(reinterpret_cast<char*>(&size), 8);
  std::string bytes(size, '\0');
  is.read(bytes.data(), static_cast<std::streamsize>(size));
  if (!is) throw IoError(f.string() + ": a tile's result file is incomplete");
  return {points, std::move(bytes)};
}

// What one tile's result file holds (several processes): the tile, then the points and bytes
// of its output records and of its outlier records (0 bytes when no outliers file is wanted).
struct PartSizes {
  std::uint64_t tile, points, bytes, outlier_points, outlier_bytes;
};

// Several processes: every process writes its own tiles' results into the outputs, in place,
// in tile order (the bytes process 0 would have appended), and syncs them; process 0 reserves
// the room first and commits the files after (finish()). The results do not travel through
// one process. `out` and `outl` are process 0's writers (null elsewhere, and outl without an
// outliers file).
void write_parts_in_place(const TileComm& comm, const std::filesystem::path& scratch,
                          const std::vector<PartSizes>& mine, PlyStreamWriter* out,
                          PlyStreamWriter* outl) {
  // Every process's tiles' sizes, hence each tile's offset in either output.
  std::string sent(mine.size() * sizeof(PartSizes), '\0');
  if (!mine.empty()) std::memcpy(sent.data(), mine.data(), sent.size());
  const std::string all = comm.allgather(sent);
  if (all.size() % sizeof(PartSizes) != 0)
    throw std::logic_error("scanclean-mpi: the tiles' sizes came back cut short");
  std::vector<PartSizes> every(all.size() / sizeof(PartSizes));
  if (!every.empty()) std::memcpy(static_cast<void*>(every.data()), all.data(), all.size());
  std::sort(every.begin(), every.end(),
            [](const PartSizes& a, const PartSizes& b) { return a.tile < b.tile; });
  std::map<std::uint64_t, std::array<std::uint64_t, 2>> offset;  // tile: output, outliers
  std::uint64_t bytes = 0, points = 0, obytes = 0, opoints = 0;
  for (const PartSizes& p : every) {
    if (!offset.emplace(p.tile, std::array<std::uint64_t, 2>{bytes, obytes}).second)
      throw std::logic_error("scanclean-mpi: two processes filtered one tile");
    bytes += p.bytes;
    points += p.points;
    obytes += p.outlier_bytes;
    opoints += p.outlier_points;
  }
  // Process 0 makes the room and tells the others where it is (they send nothing): per file,
  // the room's offset and the temporary file's path (its length first).
  std::string room;
  if (comm.rank == 0 && out) {
    for (PlyStreamWriter* w : {out, outl}) {
      if (!w) continue;
      const std::uint64_t at = w == out ? w->reserve(bytes, points) : w->reserve(obytes, opoints);
      const std::string path = w->temporary().string();
      room += std::to_string(at) + ' ' + std::to_string(path.size()) + '\n' + path;
    }
  }
  std::vector<std::pair<std::uint64_t, std::filesystem::path>> rooms;
  {
    std::istringstream in(comm.allgather(room));
    std::uint64_t at = 0;
    std::size_t length = 0;
    while (in >> at >> length && in.get() == '\n') {
      std::string path(length, '\0');
      if (!in.read(path.data(), static_cast<std::streamsize>(length))) break;
      rooms.emplace_back(at, path);
    }
    if (rooms.empty() || rooms.size() > 2)
      throw std::logic_error("scanclean-mpi: process 0's outputs came back garbled");
  }
  for (const PartSizes& p : mine) {
    const auto f = part_file(scratch, p.tile);
    std::ifstream is(f, std::ios::binary);
    if (!is) throw IoError(f.string() + ": a tile's result file is missing");
    const auto [n, cloud] = get_block(is, f);
    const auto [m, removed] = get_block(is, f);
    if (n != p.points || m != p.outlier_points)
      throw IoError(f.string() + ": a tile's result file holds other points than written");
    const std::array<std::uint64_t, 2>& at = offset.at(p.tile);
    write_at(rooms[0].second, rooms[0].first + at[0], cloud);
    if (rooms.size() > 1) write_at(rooms[1].second, rooms[1].first + at[1], removed);
    is.close();
    std::error_code ec;
    std::filesystem::remove(f, ec);
  }
  comm.allgather({});  // every result written and synced
}

// The attributes of an output as the in-memory filter makes them: the input's (select()), then
// the filter's own (set_attribute()), each taking the place and type of an input attribute of
// its name, else appended.
std::vector<std::pair<std::string, AttributeType>> with_outputs(
    std::vector<std::pair<std::string, AttributeType>> attributes,
    const std::vector<std::pair<std::string, AttributeType>>& outputs) {
  for (const auto& o : outputs) {
    const auto it = std::find_if(attributes.begin(), attributes.end(),
                                 [&](const auto& a) { return a.first == o.first; });
    if (it != attributes.end())
      it->second = o.second;
    else
      attributes.push_back(o);
  }
  return attributes;
}

}  // namespace

TiledRunResult run_tiled(const TiledRunRequest& req) {
  const auto stream = PointStream::open(req.input);
  TiledRunResult result;
  result.records = stream->size();
  TiledSource src;
  src.records = stream->size();
  src.attributes = stream->attributes();
  const PointStream* s = stream.get();
  src.read = [s](std::uint64_t first, std::uint64_t count, PointCloud& out,
                 std::vector<std::uint64_t>& rec) { s->read(first, count, out, &rec); };

  TiledOptions t = req.tiled;
  // A private scratch folder beside the output (same disk), removed at the end; with several
  // processes, named by process 0's pid, which every process learns.
  bool own_scratch = false;
  if (t.scratch.empty()) {
    std::string pid = std::to_string(::getpid());
    if (req.comm.ranks > 1 && req.comm.allgather) {
      const std::string all = req.comm.allgather(pid + '\n');
      pid = all.substr(0, all.find('\n'));
    }
    const std::filesystem::path dir = std::filesystem::absolute(req.output).parent_path();
    t.scratch = dir / (".scanclean-tiles." + pid);
    own_scratch = true;
  }
  std::error_code ec;
  std::filesystem::create_directories(t.scratch, ec);
  if (!std::filesystem::is_directory(t.scratch))
    throw IoError(t.scratch.string() + ": cannot create the scratch folder");
  // At the end, process 0 removes the private scratch folder. A run ended by an exception with
  // several processes is over for all of them (scanclean-mpi then aborts the others, which
  // leaves them no time to clean up): the process that failed removes the results of every
  // process (the folder, when private; tiled_filter has removed the tiles' scratch files).
  struct Cleanup {
    std::filesystem::path dir;
    bool own, rank0, many;
    int uncaught = std::uncaught_exceptions();
    ~Cleanup() {
      const bool failed = std::uncaught_exceptions() > uncaught;
      std::error_code e;
      if (own && (rank0 || (failed && many))) {
        std::filesystem::remove_all(dir, e);
      } else if (failed && many) {
        for (const auto& f : std::filesystem::directory_iterator(dir, e))
          if (is_part_file(f.path())) std::filesystem::remove(f.path(), e);
      }
    }
  } cleanup{t.scratch, own_scratch, req.comm.rank == 0, req.comm.ranks > 1};

  const bool rank0 = req.comm.rank == 0;
  const bool many = req.comm.ranks > 1;
  PlyLayout cloud_layout, outlier_layout;
  std::unique_ptr<AtomicCommitGroup> group;
  std::unique_ptr<PlyStreamWriter> out, outl;
  t.on_globals = [&](const TiledGlobals& g) {
    const double reach =
        std::max(g.box.min().cwiseAbs().maxCoeff(), g.box.max().cwiseAbs().maxCoeff());
    // Float keeps every coordinate within 1e-6 of the diagonal (as write_ply decides).
    const bool dbl = reach * 6.0e-8 > 1e-6 * g.box.diagonal().norm();
    cloud_layout.double_positions = outlier_layout.double_positions = dbl;
    cloud_layout.normals = true;
    outlier_layout.normals = s->has_normals();
    cloud_layout.confidences = outlier_layout.confidences = s->has_confidences();
    cloud_layout.intensities = outlier_layout.intensities = s->has_intensities();
    cloud_layout.colors = outlier_layout.colors = s->has_colors();
    // source_index: uint32 (as the in-memory outputs) while every record number fits, else
    // double (exact up to 2^53 records; PLY has no 64-bit integer type).
    const AttributeType index_type =
        s->size() > 0xffffffffULL ? AttributeType::kFloat64 : AttributeType::kUInt32;
    cloud_layout.attributes =
        with_outputs(s->attributes(), {{"likelihood", AttributeType::kFloat32},
                                       {"iterations", AttributeType::kUInt8},
                                       {"flags", AttributeType::kUInt8},
                                       {"merge_count", AttributeType::kUInt32},
                                       {"source_index", index_type},
                                       {"displacement", AttributeType::kFloat32}});
    outlier_layout.attributes = with_outputs(
        s->attributes(), {{"flags", AttributeType::kUInt8}, {"source_index", index_type}});
    if (rank0) {
      // The same provenance comment as the in-memory run's outputs (h, noise sigma, command).
      const std::string prov =
          req.provenance.empty() ? provenance_text(g.h, g.noise_sigma) : req.provenance;
      group = std::make_unique<AtomicCommitGroup>();
      out = std::make_unique<PlyStreamWriter>(req.output, cloud_layout, prov);
      if (!req.outliers.empty())
        outl = std::make_unique<PlyStreamWriter>(req.outliers, outlier_layout, prov);
    }
  };
  std::vector<PartSizes> parts;  // this process's tiles' result files (several processes)
  const TileSink sink = [&](std::size_t tile, const PointCloud& c, const PointCloud& o) {
    const std::string cb = encode_ply_vertices(c, cloud_layout);
    const std::string ob = outl || many ? encode_ply_vertices(o, outlier_layout) : std::string();
    if (!many) {
      out->append_encoded(cb, c.size());
      if (outl) outl->append_encoded(ob, o.size());
      return;
    }
    const auto f = part_file(t.scratch, tile);
    std::ofstream os(f, std::ios::binary | std::ios::trunc);
    const std::string none;
    const std::string& kept_ob = req.outliers.empty() ? none : ob;
    put_block(os, c.size(), cb);
    put_block(os, o.size(), kept_ob);
    os.close();
    if (!os) throw IoError(f.string() + ": cannot write a tile's result (disk full?)");
    parts.push_back({tile, c.size(), cb.size(), o.size(), kept_ob.size()});
  };
  result.stats = tiled_filter(src, req.filter, t, sink, req.comm);
  // The stream drops records whose x, y or z is not finite (as the whole-file readers do).
  result.dropped_invalid = result.records - std::min(result.records, result.stats.points_in);
  if (result.stats.points_in == 0)
    throw InputError(req.input.string(),
                     result.records == 0 ? std::string("no records")
                                         : "all " + std::to_string(result.records) + " records",
                     "no point with a finite x, y and z; nothing to filter");
  // (tiled_filter ends with an exchange between the processes: every part file is complete.)
  const auto& st = result.stats;
  const bool collapsed =
      (st.points_out == 0 && st.points_in >= 1) || (st.points_out == 1 && st.points_in >= 2);
  const auto writing = std::chrono::steady_clock::now();
  if (many) write_parts_in_place(req.comm, t.scratch, parts, out.get(), outl.get());
  if (rank0 && out) {
    if (!collapsed) {
      out->finish();
      if (outl) outl->finish();
      group->commit();
      result.written = true;
    }
  }
  result.seconds_writing =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - writing).count();
  if (many && req.comm.allgather) req.comm.allgather({});  // outputs committed
  return result;
}

}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_IO && SCANCLEAN_HAVE_FILTER
