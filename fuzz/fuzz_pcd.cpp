// libFuzzer target: read_pcd() on arbitrary bytes.
#include <cstddef>
#include <cstdint>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = scanclean::fuzz::write_input("in.pcd", data, size);
  scanclean::ReadReport report;
  SCANCLEAN_FUZZ_EXPECTED_ERRORS(scanclean::read_pcd(path, &report));
  return 0;
}
