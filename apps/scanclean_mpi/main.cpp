// scanclean-mpi: the tiled robust filter (tiled_filter.h) on many processes.
//   mpirun -np N scanclean-mpi IN.ply -o OUT.ply [filter options]
// Every process reads its own byte range of the input in every pass; the processes take the
// tiles one at a time, largest first, as each becomes free; every process writes its tiles'
// results into the one output in place, which process 0 commits: the same bytes for any N, and
// those of `scanclean filter --tiled` with the same options apart from the provenance comment
// (which names the command).

#include <mpi.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/core/process_memory.h"
#include "scanclean/filter_options_cli.h"
#include "scanclean/output_checks.h"
#include "scanclean/provenance.h"
#include "scanclean/summary.h"
#include "scanclean/tiled_run.h"

namespace {

// Every process's bytes, concatenated in rank order, on every process.
std::string allgather(const std::string& mine) {
  int ranks = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  const long long n = static_cast<long long>(mine.size());
  std::vector<long long> sizes(static_cast<std::size_t>(ranks));
  MPI_Allgather(&n, 1, MPI_LONG_LONG, sizes.data(), 1, MPI_LONG_LONG, MPI_COMM_WORLD);
  // Large messages go in pieces of at most 1 GiB (MPI counts are int).
  long long total = 0;
  for (long long s : sizes) total += s;
  std::string all(static_cast<std::size_t>(total), '\0');
  constexpr long long kPiece = 1LL << 30;
  long long longest = 0;
  for (long long s : sizes) longest = std::max(longest, s);
  for (long long off = 0; off < longest; off += kPiece) {
    std::vector<int> counts(static_cast<std::size_t>(ranks)), displs(counts.size());
    std::string piece;
    for (int r = 0; r < ranks; ++r) {
      const long long s = sizes[static_cast<std::size_t>(r)];
      counts[static_cast<std::size_t>(r)] =
          static_cast<int>(std::max(0LL, std::min(kPiece, s - off)));
    }
    int at = 0;
    for (int r = 0; r < ranks; ++r) {
      displs[static_cast<std::size_t>(r)] = at;
      at += counts[static_cast<std::size_t>(r)];
    }
    piece.resize(static_cast<std::size_t>(at));
    int rank = 0;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    const int mine_count = counts[static_cast<std::size_t>(rank)];
    MPI_Allgatherv(mine.data() + std::min<long long>(off, n), mine_count, MPI_CHAR, piece.data(),
                   counts.data(), displs.data(), MPI_CHAR, MPI_COMM_WORLD);
    long long dst = 0;
    for (int r = 0; r < ranks; ++r) {
      std::copy_n(piece.data() + displs[static_cast<std::size_t>(r)],
                  counts[static_cast<std::size_t>(r)],
                  all.data() + dst + std::min(off, sizes[static_cast<std::size_t>(r)]));
      dst += sizes[static_cast<std::size_t>(r)];
    }
  }
  return all;
}

// Every process's counts summed, in place (the same length on every process).
void sum(std::vector<std::uint64_t>& counts) {
  constexpr std::size_t kPiece = std::size_t{1} << 27;  // MPI counts are int
  for (std::size_t at = 0; at < counts.size(); at += kPiece)
    MPI_Allreduce(MPI_IN_PLACE, counts.data() + at,
                  static_cast<int>(std::min(kPiece, counts.size() - at)), MPI_UINT64_T, MPI_SUM,
                  MPI_COMM_WORLD);
}

// A counter in process 0's memory that every process takes the next value of (TileComm::take:
// the tiles, one at a time). Made and freed by every process together. Where the network has
// no atomic operations of its own, a take may wait until process 0 next calls MPI (at most the
// tile it is filtering).
class SharedCounter {
 public:
  explicit SharedCounter(int rank) {
    const MPI_Aint bytes = rank == 0 ? sizeof(std::uint64_t) : 0;
    MPI_Win_allocate(bytes, sizeof(std::uint64_t), MPI_INFO_NULL, MPI_COMM_WORLD, &value_, &win_);
    if (rank == 0) *value_ = 0;
    MPI_Barrier(MPI_COMM_WORLD);  // the value set before anyone takes
    MPI_Win_lock_all(MPI_MODE_NOCHECK, win_);
  }
  ~SharedCounter() {
    // Freeing is collective: after a failure MPI_Abort ends every process instead (the others
    // may be waiting elsewhere).
    if (std::uncaught_exceptions() > uncaught_) return;
    MPI_Win_unlock_all(win_);
    MPI_Win_free(&win_);
  }
  SharedCounter(const SharedCounter&) = delete;
  SharedCounter& operator=(const SharedCounter&) = delete;
  std::uint64_t take() {
    const std::uint64_t one = 1;
    std::uint64_t got = 0;
    MPI_Fetch_and_op(&one, &got, MPI_UINT64_T, 0, 0, MPI_SUM, win_);
    MPI_Win_flush(0, win_);
    return got;
  }

 private:
  MPI_Win win_ = MPI_WIN_NULL;
  std::uint64_t* value_ = nullptr;
  int uncaught_ = std::uncaught_exceptions();
};

int run(int argc, char** argv, int rank, int ranks) {
  using namespace scanclean;
  using namespace scanclean::app;
  CLI::App cli{
      "scanclean-mpi: the robust filter by tiles on many processes (run it with mpirun -np N).\n"
      "Input: one binary PLY or binary PCD (metres); output: binary PLY, identical for any N.",
      "scanclean-mpi"};
  std::string input, output, outliers, budget, scratch;
  double halo = 4.0;
  cli.add_option("input", input, "Input point cloud (binary .ply or .pcd, metres)")->required();
  cli.add_option("-o,--output", output, "Output point cloud (.ply)")->required();
  cli.add_option("--outliers", outliers, "Write the removed input points here (.ply)");
  cli.add_option("--memory-budget", budget,
                 "Peak memory per process, e.g. 2G (default: 2G, or half the machine's memory "
                 "if less; processes on one machine share it: give each its part)");
  cli.add_option("--scratch", scratch,
                 "Folder for the scratch files, shared by every process (default: beside the "
                 "output)");
  cli.add_option("--halo", halo, "The halo around each tile, in units of h (default 4)");
  auto values = add_filter_options(cli);
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = rank == 0 ? cli.exit(e) : (e.get_exit_code() == 0 ? 0 : 1);
    return rc == 0 ? 0 : static_cast<int>(ExitCode::kBadOptions);
  }
  set_command_line(argc, argv, "scanclean-mpi");  // the outputs' provenance comment
  check_input_files("scanclean-mpi", {{"input", input}});
  check_output_files("scanclean-mpi", {{"input", input}},
                     {{"-o", output}, {"--outliers", outliers}});
  TiledRunRequest req;
  req.input = input;
  req.output = output;
  req.outliers = outliers;
  req.filter = to_filter_options(*values);
  req.tiled.memory_budget =
      budget.empty() ? default_memory_budget() : parse_memory_size("--memory-budget", budget);
  req.tiled.halo_factor = halo;
  if (!scratch.empty()) req.tiled.scratch = scratch;
  req.comm.rank = rank;
  req.comm.ranks = ranks;
  req.comm.allgather = allgather;
  req.comm.sum = sum;
  SharedCounter tiles(rank);
  req.comm.take = [&tiles] { return tiles.take(); };
  const TiledRunResult r = run_tiled(req);
  const TiledStats& s = r.stats;
  // Per-process figures to process 0, which prints them.
  char line[256];
  std::snprintf(line, sizeof line, "%d %zu %llu %.3f %.3f %.1f\n", rank, s.tiles_here,
                static_cast<unsigned long long>(s.halo_points), s.seconds_tiles, r.seconds_writing,
                static_cast<double>(s.peak_rss_bytes) / 1048576.0);
  const std::string per_rank = allgather(line);
  if (rank == 0) {
    Summary sum("scanclean-mpi");
    sum.add("processes", std::to_string(ranks));
    if (r.dropped_invalid > 0) sum.add_count("invalid dropped", r.dropped_invalid);
    sum.add_count("points in", s.points_in);
    sum.add_count("points out", s.points_out);
    sum.add_count("outliers removed", s.outliers);
    sum.add("h", s.globals.h * 1000.0, 3, "mm");
    sum.add("tiles", std::to_string(s.tiles));
    sum.add("output file", r.written ? output : "not written (collapsed result)");
    sum.add("total", s.seconds_total, 2, "s");
    sum.add_count(
        "points per second",
        static_cast<unsigned long long>(s.seconds_total > 0 ? s.points_in / s.seconds_total : 0));
    sum.print();
    std::printf("rank tiles halo_points tile_seconds write_seconds peak_MiB\n%s", per_rank.c_str());
    std::fflush(stdout);
    warn_dropped_invalid(input, r.dropped_invalid);
    if (r.written) warn_if_mostly_unsupported(s.unsupported, s.points_in, s.globals.h);
  }
  const bool collapsed =
      (s.points_out == 0 && s.points_in >= 1) || (s.points_out == 1 && s.points_in >= 2);
  return collapsed ? static_cast<int>(ExitCode::kEmptyResult) : 0;
}

}  // namespace

int main(int argc, char** argv) {
  scanclean::keep_freed_arrays_for_reuse();  // before MPI_Init, which allocates too
  MPI_Init(&argc, &argv);
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  int rc = 0;
  try {
    rc = run(argc, argv, rank, ranks);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scanclean-mpi (process %d): error: %s\n", rank, e.what());
    rc = static_cast<int>(scanclean::exit_code_for(e));
    // One process failing leaves the others waiting in a collective: stop them all.
    MPI_Abort(MPI_COMM_WORLD, rc);
  }
  MPI_Finalize();
  return rc;
}
