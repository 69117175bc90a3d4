#pragma once
//! \file atomic_file.h
//! Atomic file output: everything is written to a temporary file beside the target
//! (".<name>.tmp.<pid>.<n>"), which is renamed over the target only by commit(). A failed or
//! abandoned write never leaves a half file in place. commit() checks every fsync, and syncs the
//! folder after the rename so that the rename itself survives a power loss. Temporary files left
//! by a killed process (its pid no longer running) are removed the first time this process writes
//! into the same folder; stale_temporaries_removed() counts them.

#include <cstddef>
#include <filesystem>
#include <fstream>
#include <functional>
#include <ostream>
#include <utility>
#include <vector>

namespace scanclean {

class AtomicCommitGroup;

class AtomicFile {
 public:
  //! Creates the temporary file. \throw IoError if it cannot be created (naming the folder when
  //! the folder is missing).
  explicit AtomicFile(std::filesystem::path target, bool binary = true);
  ~AtomicFile();  //!< removes the temporary file unless commit() succeeded
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::ostream& stream() { return out_; }
  //! Flushes, syncs and renames the temporary file over the target, then syncs the folder.
  //! While an AtomicCommitGroup is open on this thread, the rename is left to the group.
  //! \throw IoError.
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

//! Several atomic writes committed together (e.g. a cleaned cloud and its outliers file): while
//! the group is open on this thread, AtomicFile::commit() writes and syncs its temporary file but
//! does not rename it. commit() renames them all (after all were written); a group destroyed
//! without commit() removes its temporary files, so none of its targets changes.
class AtomicCommitGroup {
 public:
  AtomicCommitGroup();
  ~AtomicCommitGroup();
  AtomicCommitGroup(const AtomicCommitGroup&) = delete;
  AtomicCommitGroup& operator=(const AtomicCommitGroup&) = delete;
  //! Renames every staged file over its target and syncs the folders; closes the group.
  //! \throw IoError.
  void commit();

 private:
  friend class AtomicFile;
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> staged_;  // temp, target
  AtomicCommitGroup* previous_ = nullptr;
  bool open_ = true;
};

//! Temporary files of dead processes removed so far by this process.
std::size_t stale_temporaries_removed();

}  // namespace scanclean
