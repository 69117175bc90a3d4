#pragma once
//! \file atomic_file.h
//! Atomic file output: everything is written to a temporary file beside the target, which is
//! renamed over the target only by commit(). A failed or abandoned write never leaves a half
//! file in place.

#include <filesystem>
#include <fstream>
#include <functional>
#include <ostream>

namespace scanclean {

class AtomicFile {
 public:
  //! Creates the temporary file. \throw IoError if it cannot be created.
  explicit AtomicFile(std::filesystem::path target, bool binary = true);
  ~AtomicFile();  //!< removes the temporary file unless commit() succeeded
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::ostream& stream() { return out_; }
  //! Flushes, syncs and renames the temporary file over the target. \throw IoError.
  void commit();
  const std::filesystem::path& target() const { return target_; }
  const std::filesystem::path& temporary() const { return temp_; }

 private:
  std::filesystem::path target_;
  std::filesystem::path temp_;
  std::ofstream out_;
  bool committed_ = false;
};

//! Writes a file atomically through `write`. \throw IoError (and whatever `write` throws; the
//! target is then left untouched).
void write_file_atomically(const std::filesystem::path& target,
                           const std::function<void(std::ostream&)>& write, bool binary = true);

}  // namespace scanclean
