#include "tile_exchange.h"

namespace scanclean::detail {

std::vector<std::string> allgather(const TileComm& comm, const std::string& mine) {
  if (comm.ranks <= 1 || !comm.allgather) return {mine};
  // Each message framed by its length: comm.allgather concatenates them.
  MessageWriter framed;
  framed.put<std::uint64_t>(mine.size());
  framed.bytes += mine;
  const std::string all = comm.allgather(framed.bytes);
  std::vector<std::string> out;
  MessageReader r{all};
  while (!r.done()) {
    const auto n = r.get<std::uint64_t>();
    if (n > all.size() - r.at) throw std::logic_error("tiled filter: short message");
    out.push_back(all.substr(r.at, n));
    r.at += n;
  }
  if (out.size() != static_cast<std::size_t>(comm.ranks))
    throw std::logic_error("tiled filter: allgather returned the wrong number of messages");
  return out;
}

bool sum_histograms_as_arrays(const TileComm& comm, const std::vector<std::uint64_t>& hist) {
  if (comm.ranks <= 1 || !comm.sum) return false;
  MessageWriter mine;
  mine.put<std::uint64_t>(static_cast<std::uint64_t>(
      std::count_if(hist.begin(), hist.end(), [](std::uint64_t n) { return n > 0; })));
  std::uint64_t occupied = 0;
  for (const std::string& m : allgather(comm, mine.bytes))
    occupied += MessageReader{m}.get<std::uint64_t>();
  return occupied * 2 > hist.size();
}

std::array<std::uint64_t, 2> record_range(std::uint64_t records, const TileComm& comm) {
  const auto n = static_cast<std::uint64_t>(std::max(1, comm.ranks));
  const auto at = [&](std::uint64_t k) { return records / n * k + records % n * k / n; };
  return {at(static_cast<std::uint64_t>(comm.rank)), at(static_cast<std::uint64_t>(comm.rank) + 1)};
}

}  // namespace scanclean::detail
