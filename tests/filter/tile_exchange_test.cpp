// What the processes of a tiled run exchange (filter/src/tile_exchange.h): messages read back
// as written, a short message refused, every process's message in rank order, and record
// ranges that split the records among the processes.
#include "../../filter/src/tile_exchange.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <array>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

#include "tiled_test_support.h"

namespace scanclean::detail {
namespace {

TEST(TileExchange, AMessageReadsBackWhatWasPutInOrder) {
  MessageWriter w;
  w.put<std::uint64_t>(0x0123456789abcdefULL);
  w.put(Eigen::Vector3d(1.5, -2.25, 1e300));
  w.put_vec(std::vector<float>{});
  w.put_vec(std::vector<std::uint64_t>{7, 0, std::numeric_limits<std::uint64_t>::max()});
  w.put<char>('\0');
  w.put_vec(std::vector<std::array<std::uint8_t, 4>>{{1, 2, 3, 4}});
  EXPECT_EQ(w.bytes.size(), 8u + 24 + 8 + (8 + 24) + 1 + (8 + 4));
  MessageReader r{w.bytes};
  EXPECT_EQ(r.get<std::uint64_t>(), 0x0123456789abcdefULL);
  EXPECT_EQ(r.get<Eigen::Vector3d>(), Eigen::Vector3d(1.5, -2.25, 1e300));
  EXPECT_TRUE(r.get_vec<float>().empty());
  EXPECT_EQ(r.get_vec<std::uint64_t>(),
            (std::vector<std::uint64_t>{7, 0, std::numeric_limits<std::uint64_t>::max()}));
  EXPECT_FALSE(r.done());
  EXPECT_EQ(r.get<char>(), '\0');
  const auto v = r.get_vec<std::array<std::uint8_t, 4>>();
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0], (std::array<std::uint8_t, 4>{1, 2, 3, 4}));
  EXPECT_TRUE(r.done());
}

TEST(TileExchange, AShortMessageIsRefused) {
  MessageWriter w;
  w.put<std::uint32_t>(5);
  {
    MessageReader r{w.bytes};
    EXPECT_THROW(r.get<std::uint64_t>(), std::logic_error);
  }
  // A vector announcing more elements than follow, and one whose byte count would overflow.
  for (const std::uint64_t n : {std::uint64_t{3}, std::numeric_limits<std::uint64_t>::max() / 4}) {
    MessageWriter v;
    v.put<std::uint64_t>(n);
    v.put<double>(1.0);
    v.put<double>(2.0);
    MessageReader r{v.bytes};
    EXPECT_THROW(r.get_vec<double>(), std::logic_error) << n;
  }
}

TEST(TileExchange, OneProcessGetsItsOwnMessage) {
  const std::string mine("a\0b", 3);
  EXPECT_EQ(allgather(TileComm{}, mine), std::vector<std::string>{mine});
}

TEST(TileExchange, EveryProcessGetsEveryMessageInRankOrder) {
  // Three processes, messages of different lengths with zero bytes, one of them empty.
  const std::vector<std::string> sent = {std::string("\0\1\2", 3), std::string(), "rank two"};
  const std::vector<std::vector<std::string>> got =
      test::run_ranks<std::vector<std::string>>(3, [&](const TileComm& comm) {
        return allgather(comm, sent[static_cast<std::size_t>(comm.rank)]);
      });
  for (const auto& g : got) EXPECT_EQ(g, sent);
}

TEST(TileExchange, AnExchangeWithTooFewMessagesIsRefused) {
  // An exchange that drops the last process's message.
  TileComm comm = test::process_of(0, 3);
  comm.allgather = [](const std::string& mine) { return mine + mine; };
  EXPECT_THROW(allgather(comm, "x"), std::logic_error);
  // One that cuts a message short.
  TileComm cut = test::process_of(0, 2);
  cut.allgather = [](const std::string& mine) { return mine + mine.substr(0, mine.size() - 1); };
  EXPECT_THROW(allgather(cut, "xyz"), std::logic_error);
}

TEST(TileExchange, HistogramsAreSummedAsArraysOnlyWhenTheirOccupiedCellsWouldOutweighThem) {
  // 600 cells; each process occupies `per_rank` of them (16 bytes each when gathered) against
  // 8 bytes a cell of the array: the arrays win above 300 occupied cells in all.
  const auto decide = [](int ranks, std::size_t per_rank, bool with_sum) {
    const std::vector<std::uint8_t> got =
        test::run_ranks<std::uint8_t>(ranks, [&](const TileComm& comm) {
          std::vector<std::uint64_t> hist(600, 0);
          for (std::size_t i = 0; i < per_rank; ++i)  // spread over the grid, one count each
            hist[(i * 7 + static_cast<std::size_t>(comm.rank)) % hist.size()] = 1 + i % 3;
          TileComm c = comm;
          if (!with_sum) c.sum = nullptr;
          return sum_histograms_as_arrays(c, hist) ? std::uint8_t{1} : std::uint8_t{0};
        });
    for (std::uint8_t g : got) EXPECT_EQ(g, got[0]) << "the processes disagree";
    return got[0] != 0;
  };
  EXPECT_FALSE(decide(3, 100, true));   // 300 in all: gathered, 4,800 bytes = the array's
  EXPECT_TRUE(decide(3, 101, true));    // 303
  EXPECT_TRUE(decide(2, 600, true));    // every cell on each
  EXPECT_FALSE(decide(2, 600, false));  // no sum to call
  EXPECT_FALSE(decide(1, 600, true));   // one process exchanges nothing
}

TEST(TileExchange, RecordRangesSplitTheRecordsEvenlyInRankOrder) {
  for (const std::uint64_t records : {0ULL, 1ULL, 7ULL, 10ULL, 1000003ULL})
    for (int ranks = 1; ranks <= 7; ++ranks) {
      std::uint64_t next = 0, smallest = records, largest = 0;
      for (int r = 0; r < ranks; ++r) {
        const auto [b, e] = record_range(records, test::process_of(r, ranks));
        EXPECT_EQ(b, next) << records << " records, rank " << r << " of " << ranks;
        ASSERT_LE(b, e);
        smallest = std::min(smallest, e - b);
        largest = std::max(largest, e - b);
        next = e;
      }
      EXPECT_EQ(next, records) << ranks;
      EXPECT_LE(largest - smallest, 1u) << records << " records, " << ranks << " ranks";
    }
}

}  // namespace
}  // namespace scanclean::detail
