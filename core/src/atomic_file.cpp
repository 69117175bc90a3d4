#include "scanclean/core/atomic_file.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <set>
#include <string>
#include <system_error>

#include "scanclean/core/errors.h"

namespace scanclean {

namespace {

thread_local AtomicCommitGroup* t_group = nullptr;
std::atomic<std::size_t> g_stale_removed{0};

std::filesystem::path folder_of(const std::filesystem::path& target) {
  return target.parent_path().empty() ? std::filesystem::path(".") : target.parent_path();
}

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

// Removes ".<anything>.tmp.<pid>.<n>" files in `dir` whose process is gone; once per folder.
void remove_stale_temporaries(const std::filesystem::path& dir) {
  static std::mutex mutex;
  static std::set<std::string> done;
  std::error_code ec;
  const std::string key = std::filesystem::absolute(dir, ec).lexically_normal().string();
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (!done.insert(key).second) return;
  }
  std::filesystem::directory_iterator it(dir, ec), end;
  for (; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() < 8 || name[0] != '.') continue;
    const auto tmp = name.rfind(".tmp.");
    if (tmp == std::string::npos || tmp == 0) continue;
    const std::string rest = name.substr(tmp + 5);  // "<pid>.<n>"
    const auto dot = rest.find('.');
    if (dot == std::string::npos || dot == 0) continue;
    long pid = 0;
    bool digits = true;
    for (std::size_t i = 0; i < rest.size(); ++i) {
      if (i == dot) continue;
      if (rest[i] < '0' || rest[i] > '9') digits = false;
    }
    if (!digits || dot > 9) continue;
    pid = std::stol(rest.substr(0, dot));
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive (or unknown)
    std::error_code rm;
    if (std::filesystem::remove(it->path(), rm)) ++g_stale_removed;
  }
}

void sync_path(const std::filesystem::path& p, const std::string& what, bool directory) {
  const int fd = ::open(p.c_str(), directory ? (O_RDONLY | O_DIRECTORY) : O_RDONLY);
  if (fd < 0)
    throw IoError(what + ": cannot open " + p.string() + " to sync: " + std::strerror(errno));
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  // Some file systems cannot sync a folder (EINVAL); the rename is then as durable as they allow.
  if (rc != 0 && !(directory && (err == EINVAL || err == EROFS)))
    throw IoError(what + ": fsync of " + p.string() + " failed: " + std::strerror(err));
}

}  // namespace

AtomicFile::AtomicFile(std::filesystem::path target, bool binary)
    : target_(std::move(target)), temp_(make_temp_name(target_)) {
  const std::filesystem::path dir = folder_of(target_);
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec))
    throw IoError(target_.string() + ": the folder \"" + dir.string() + "\" does not exist");
  remove_stale_temporaries(dir);
  out_.open(temp_, binary ? std::ios::out | std::ios::binary | std::ios::trunc
                          : std::ios::out | std::ios::trunc);
  if (!out_)
    throw IoError(target_.string() + ": cannot create a file in the folder \"" + dir.string() +
                  "\": " + std::strerror(errno));
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
  sync_path(temp_, target_.string(), false);
  if (t_group != nullptr) {
    t_group->staged_.emplace_back(temp_, target_);
    committed_ = true;  // the group owns the temporary file now
    return;
  }
  std::error_code ec;
  std::filesystem::rename(temp_, target_, ec);
  if (ec) throw IoError(target_.string() + ": cannot rename temporary file: " + ec.message());
  committed_ = true;
  sync_path(folder_of(target_), target_.string(), true);
}

void write_file_atomically(const std::filesystem::path& target,
                           const std::function<void(std::ostream&)>& write, bool binary) {
  AtomicFile file(target, binary);
  write(file.stream());
  file.commit();
}

AtomicCommitGroup::AtomicCommitGroup() : previous_(t_group) {
  t_group = this;
}

AtomicCommitGroup::~AtomicCommitGroup() {
  if (open_) t_group = previous_;
  for (const auto& [temp, target] : staged_) {
    std::error_code ec;
    std::filesystem::remove(temp, ec);
  }
}

void AtomicCommitGroup::commit() {
  if (open_) {
    t_group = previous_;
    open_ = false;
  }
  std::set<std::string> folders;
  while (!staged_.empty()) {
    const auto [temp, target] = staged_.front();
    std::error_code ec;
    std::filesystem::rename(temp, target, ec);
    if (ec) throw IoError(target.string() + ": cannot rename temporary file: " + ec.message());
    staged_.erase(staged_.begin());
    folders.insert(folder_of(target).string());
  }
  for (const auto& f : folders) sync_path(f, f, true);
}

std::size_t stale_temporaries_removed() {
  return g_stale_removed.load();
}

}  // namespace scanclean
