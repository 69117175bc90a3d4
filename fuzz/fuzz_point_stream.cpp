// libFuzzer target: PointStream (the tiled filter's streaming reader of binary PLY and PCD) on
// arbitrary bytes: open, then every record read back by ranges as 1 and 3 processes would, in
// small chunks. Besides the typed exceptions, a broken promise of the reader is a finding: a
// record index outside the range asked for or out of order, or a point with a non-finite
// coordinate (those are dropped).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/point_stream.h"

namespace {

void check(bool ok) {
  if (!ok) std::abort();  // a finding: libFuzzer reports it as a crash
}

void read_all(const scanclean::PointStream& s) {
  const std::uint64_t n = s.size();
  if (n > (std::uint64_t{1} << 20)) return;  // a header that declares more than the fuzz input
  for (int ranks : {1, 3})
    for (int rank = 0; rank < ranks; ++rank) {
      const auto range = scanclean::PointStream::split(n, rank, ranks);
      const std::uint64_t b = range[0], e = range[1];
      check(b <= e && e <= n);
      std::uint64_t last = b;
      bool first = true;
      s.for_each_chunk(b, e - b, 5,
                       [&](const scanclean::PointCloud& c, const std::vector<std::uint64_t>& rec) {
                         check(rec.size() == c.size());
                         // Every chunk holds the announced attributes, a value per point.
                         check(c.attributes.size() == s.attributes().size());
                         for (std::size_t a = 0; a < c.attributes.size(); ++a)
                           check(c.attributes[a].name == s.attributes()[a].first &&
                                 c.attributes[a].values.size() == c.size());
                         for (std::size_t i = 0; i < c.size(); ++i) {
                           check(rec[i] >= b && rec[i] < e);
                           check(first || rec[i] > last);
                           first = false;
                           last = rec[i];
                           check(c.positions[i].allFinite());
                         }
                       });
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // The extension names the format: a PLY starts with "ply".
  const bool ply = size >= 3 && data[0] == 'p' && data[1] == 'l' && data[2] == 'y';
  const auto path = scanclean::fuzz::write_input(ply ? "in.ply" : "in.pcd", data, size);
  SCANCLEAN_FUZZ_EXPECTED_ERRORS({
    const auto s = scanclean::PointStream::open(path);
    read_all(*s);
  });
  return 0;
}
