#include "scanclean/core/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <string>
#include <system_error>

#include "scanclean/core/errors.h"

namespace scanclean {

namespace {
std::filesystem::path make_temp_name(const std::filesystem::path& target) {
  static std::atomic<unsigned> counter{0};
  std::filesystem::path dir = target.parent_path();
  std::string name(".");
  name += target.filename().string();
  name += ".tmp.";
  name += std::to_string(::getpid());
  name += '.';
  name += std::to_string(counter++);
  return dir.empty() ? std::filesystem::path(name) : dir / name;
}

void sync_file(const std::filesystem::path& p) {
  int fd = ::open(p.c_str(), O_RDONLY);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}
}  // namespace

AtomicFile::AtomicFile(std::filesystem::path target, bool binary)
    : target_(std::move(target)), temp_(make_temp_name(target_)) {
  out_.open(temp_, binary ? std::ios::out | std::ios::binary | std::ios::trunc
                          : std::ios::out | std::ios::trunc);
  if (!out_)
    throw IoError(target_.string() + ": cannot create temporary file " + temp_.string() + ": " +
                  std::strerror(errno));
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    out_.close();
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicFile::commit() {
  out_.flush();
  if (!out_) throw IoError(target_.string() + ": write failed (disk full?)");
  out_.close();
  if (out_.fail()) throw IoError(target_.string() + ": closing the temporary file failed");
  sync_file(temp_);
  std::error_code ec;
  std::filesystem::rename(temp_, target_, ec);
  if (ec) throw IoError(target_.string() + ": cannot rename temporary file: " + ec.message());
  committed_ = true;
}

void write_file_atomically(const std::filesystem::path& target,
                           const std::function<void(std::ostream&)>& write, bool binary) {
  AtomicFile file(target, binary);
  write(file.stream());
  file.commit();
}

}  // namespace scanclean
