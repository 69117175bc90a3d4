#include "oni_header.h"

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <cstring>

namespace scanclean::oni {
namespace {

template <typename T>
T load_le(const unsigned char* p) {
  T v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) v |= static_cast<T>(p[i]) << (8 * i);
  return v;
}

//! Reads the 24 header bytes through `fd`; false when the file is shorter or not NI10.
bool read_bytes(int fd, std::array<unsigned char, kHeaderSize>& bytes) {
  std::size_t got = 0;
  while (got < bytes.size()) {
    const ssize_t n = ::pread(fd, bytes.data() + got, bytes.size() - got, static_cast<off_t>(got));
    if (n <= 0) return false;
    got += static_cast<std::size_t>(n);
  }
  return std::memcmp(bytes.data(), "NI10", 4) == 0;
}

}  // namespace

std::optional<Header> read_header(const std::filesystem::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return std::nullopt;
  std::array<unsigned char, kHeaderSize> b{};
  const bool ok = read_bytes(fd, b);
  ::close(fd);
  if (!ok) return std::nullopt;
  Header h;
  h.major = b[4];
  h.minor = b[5];
  h.maintenance = load_le<std::uint16_t>(&b[6]);
  h.build = load_le<std::uint32_t>(&b[8]);
  h.max_timestamp = load_le<std::uint64_t>(&b[12]);
  h.max_node_id = load_le<std::uint32_t>(&b[kMaxNodeIdOffset]);
  return h;
}

bool ensure_max_node_id(const std::filesystem::path& file, std::uint32_t streams) {
  const int fd = ::open(file.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) return false;
  std::array<unsigned char, kHeaderSize> b{};
  bool ok = read_bytes(fd, b);
  if (ok && load_le<std::uint32_t>(&b[kMaxNodeIdOffset]) < streams) {
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
