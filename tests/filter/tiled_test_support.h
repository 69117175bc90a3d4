#pragma once
// Test support for the tiled filter (tiled_filter.h and filter/src/tile_*.h): a scratch folder,
// a source that reads an in-memory cloud by record ranges, and processes played by threads of
// one test that exchange their messages as MPI's allgather and allreduce (sum) would, and
// share a counter as MPI_Fetch_and_op on one would.

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <exception>
#include <filesystem>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/filter/tiled_filter.h"

namespace scanclean::test {

// A scratch folder of one test's own, removed when the test ends; options() puts a tiled run
// there, in many chunks.
struct ScratchDir {
  std::filesystem::path path;
  explicit ScratchDir(const std::string& name)
      : path(std::filesystem::temp_directory_path() /
             ("scanclean_tiled_" + name + "_" + std::to_string(::getpid()))) {
    std::filesystem::create_directories(path);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  TiledOptions options(std::uint64_t max_tile_points) const {
    TiledOptions t;
    t.scratch = path;
    t.max_tile_points = max_tile_points;
    t.chunk_records = 7000;  // many chunks
    return t;
  }
};

// Reads records [first, first + count) of c (every record valid), record numbers = indices.
inline TiledSource source_of(const PointCloud& c) {
  TiledSource s;
  s.records = c.size();
  for (const Attribute& a : c.attributes) s.attributes.emplace_back(a.name, a.type);
  s.read = [&c](std::uint64_t first, std::uint64_t count, PointCloud& out,
                std::vector<std::uint64_t>& rec) {
    const std::uint64_t end = std::min<std::uint64_t>(c.size(), first + count);
    std::vector<std::size_t> idx;
    rec.clear();
    for (std::uint64_t i = first; i < end; ++i) {
      idx.push_back(static_cast<std::size_t>(i));
      rec.push_back(i);
    }
    out = select(c, idx);
  };
  return s;
}

// Process `rank` of `ranks`, without an exchange (for what needs only the numbers).
inline TileComm process_of(int rank, int ranks) {
  TileComm comm;
  comm.rank = rank;
  comm.ranks = ranks;
  return comm;
}

// The exchange of `ranks` processes played by threads: each allgather(rank, bytes) waits for
// every rank's call and returns their bytes concatenated in rank order. fail() ends every
// waiting and later call with an exception, as a process that MPI aborts.
class RankExchange {
 public:
  explicit RankExchange(int ranks) : slot_(static_cast<std::size_t>(ranks)) {}
  std::string allgather(int rank, const std::string& mine) {
    std::unique_lock lock(m_);
    if (failed_) throw std::runtime_error("aborted");
    slot_[static_cast<std::size_t>(rank)] = mine;
    const int gen = generation_;
    if (++arrived_ == static_cast<int>(slot_.size())) {
      joined_.clear();
      for (const std::string& s : slot_) joined_ += s;
      arrived_ = 0;
      ++generation_;
      cv_.notify_all();
      return joined_;
    }
    cv_.wait(lock, [&] { return generation_ != gen || failed_; });
    if (generation_ == gen) throw std::runtime_error("aborted");
    return joined_;
  }
  void fail() {
    const std::lock_guard lock(m_);
    failed_ = true;
    cv_.notify_all();
  }
  // As MPI_Allreduce's sum: every rank's counts (of one length), summed in rank order.
  void sum(int rank, std::vector<std::uint64_t>& counts) {
    const std::string mine(reinterpret_cast<const char*>(counts.data()),
                           counts.size() * sizeof(std::uint64_t));
    const std::string all = allgather(rank, mine);
    if (all.size() != slot_.size() * mine.size())
      throw std::logic_error("RankExchange::sum: the ranks' counts differ in length");
    std::fill(counts.begin(), counts.end(), 0);
    for (std::size_t r = 0; r < slot_.size(); ++r)
      for (std::size_t i = 0; i < counts.size(); ++i) {
        std::uint64_t n;
        std::memcpy(&n, all.data() + r * mine.size() + i * sizeof n, sizeof n);
        counts[i] += n;
      }
  }
  // As MPI_Fetch_and_op on a counter: the next value, to one caller.
  std::uint64_t take() { return taken_.fetch_add(1); }
  TileComm comm(int rank) {
    return {rank, static_cast<int>(slot_.size()),
            [this, rank](const std::string& b) { return allgather(rank, b); },
            [this, rank](std::vector<std::uint64_t>& c) { sum(rank, c); },
            [this] { return take(); }};
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  std::vector<std::string> slot_;
  std::string joined_;
  int arrived_ = 0, generation_ = 0;
  bool failed_ = false;
  std::atomic<std::uint64_t> taken_{0};
};

// Runs f(comm) as each of `ranks` processes, one thread each, and returns their results in rank
// order. An exception in one process fails the exchange (the others stop) and is rethrown: the
// first one thrown, not the others' "aborted".
template <class R>
std::vector<R> run_ranks(int ranks, const std::function<R(const TileComm&)>& f) {
  RankExchange exchange(ranks);
  std::vector<R> out(static_cast<std::size_t>(ranks));
  std::mutex m;
  std::exception_ptr first_error;
  std::vector<std::thread> threads;
  for (int r = 0; r < ranks; ++r)
    threads.emplace_back([&, r] {
      try {
        out[static_cast<std::size_t>(r)] = f(exchange.comm(r));
      } catch (...) {
        {
          const std::lock_guard lock(m);
          if (!first_error) first_error = std::current_exception();
        }
        exchange.fail();
      }
    });
  for (std::thread& t : threads) t.join();
  if (first_error) std::rethrow_exception(first_error);
  return out;
}

}  // namespace scanclean::test
