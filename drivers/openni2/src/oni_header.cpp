#include "oni_header.h"

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <cstring>

namespace scanclean::oni {
namespace {

//! The NI10 header's maximum node id through `fd`; nullopt when the file is shorter or not NI10.
std::optional<std::uint32_t> max_node_id(int fd) {
  std::array<unsigned char, kHeaderSize> b{};
  std::size_t got = 0;
  while (got < b.size()) {
    const ssize_t n = ::pread(fd, b.data() + got, b.size() - got, static_cast<off_t>(got));
    if (n <= 0) return std::nullopt;
    got += static_cast<std::size_t>(n);
  }
  if (std::memcmp(b.data(), "NI10", 4) != 0) return std::nullopt;
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < 4; ++i) v |= std::uint32_t{b[kMaxNodeIdOffset + i]} << (8 * i);
  return v;
}

}  // namespace

std::optional<std::uint32_t> read_max_node_id(const std::filesystem::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return std::nullopt;
  const auto id = max_node_id(fd);
  ::close(fd);
  return id;
}

bool ensure_max_node_id(const std::filesystem::path& file, std::uint32_t streams) {
  const int fd = ::open(file.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) return false;
  const auto id = max_node_id(fd);
  bool ok = id.has_value();
  if (ok && *id < streams) {
    std::array<unsigned char, 4> v{};
    for (std::size_t i = 0; i < v.size(); ++i)
      v[i] = static_cast<unsigned char>(streams >> (8 * i));
    ok = ::pwrite(fd, v.data(), v.size(), static_cast<off_t>(kMaxNodeIdOffset)) ==
         static_cast<ssize_t>(v.size());
  }
  ::close(fd);
  return ok;
}

}  // namespace scanclean::oni
