#pragma once
//! Internal: how the processes of a tiled run (tiled_filter.h) share the work: each reads its
//! own range of the records, and what they tell each other travels as messages of raw values,
//! gathered from every process in rank order.

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/filter/tiled_filter.h"

namespace scanclean::detail {

//! A message: trivially copyable values appended as their bytes, read back in the same order
//! by MessageReader (every process runs the same program on the same kind of machine).
struct MessageWriter {
  std::string bytes;
  template <class T>
  void put(const T& v) {
    bytes.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  //! The element count, then the elements.
  template <class T>
  void put_vec(const std::vector<T>& v) {
    put<std::uint64_t>(v.size());
    bytes.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }
};

//! Reads a MessageWriter's values in the order they were put. \throw std::logic_error when the
//! message ends before the value (a program error: the processes disagree on the layout).
struct MessageReader {
  const std::string& bytes;
  std::size_t at = 0;
  bool done() const { return at >= bytes.size(); }
  template <class T>
  T get() {
    if (at + sizeof(T) > bytes.size()) throw std::logic_error("tiled filter: short message");
    T v;
    std::memcpy(static_cast<void*>(&v), bytes.data() + at, sizeof(T));
    at += sizeof(T);
    return v;
  }
  template <class T>
  std::vector<T> get_vec() {
    const auto n = get<std::uint64_t>();
    if (n > (bytes.size() - at) / sizeof(T)) throw std::logic_error("tiled filter: short message");
    std::vector<T> v(n);
    if (n > 0)  // (an empty v has no data)
      std::memcpy(static_cast<void*>(v.data()), bytes.data() + at, n * sizeof(T));
    at += n * sizeof(T);
    return v;
  }
};

//! Every process's message, in rank order (only `mine` with one process). Every process of
//! `comm` must call it, in the same order as the others. \throw std::logic_error when the
//! exchange returns another number of messages than processes.
std::vector<std::string> allgather(const TileComm& comm, const std::string& mine);

//! Whether the processes' histograms of `hist.size()` cells are summed as whole arrays
//! (comm.sum) rather than gathered as their occupied cells: when comm.sum is given and the cells
//! occupied on every process, gathered (16 bytes each), would take more than the array (8 bytes
//! a cell) that comm.sum reduces. Every process of `comm` must call it (it gathers their counts
//! of occupied cells) and gets the same answer. False for one process.
bool sum_histograms_as_arrays(const TileComm& comm, const std::vector<std::uint64_t>& hist);

//! The records this process reads, [first, last): the records split into comm.ranks ranges in
//! rank order, whose sizes differ by at most one.
std::array<std::uint64_t, 2> record_range(std::uint64_t records, const TileComm& comm);

//! Reads records [b, e) of the source, `chunk` at a time, calling f(cloud, record numbers) per
//! chunk (the source leaves out invalid records, so the cloud may hold fewer).
template <class F>
void stream_records(const TiledSource& src, std::uint64_t b, std::uint64_t e, std::size_t chunk,
                    F&& f) {
  PointCloud c;
  std::vector<std::uint64_t> rec;
  for (std::uint64_t at = b; at < e; at += chunk) {
    src.read(at, std::min<std::uint64_t>(chunk, e - at), c, rec);
    f(c, rec);
  }
}

}  // namespace scanclean::detail
