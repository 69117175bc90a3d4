#include "scanclean/core/atomic_file.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <stdexcept>

#include "scanclean/core/errors.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(AtomicFileTest, CommitReplacesTargetAndLeavesNoTemporary) {
  auto dir = test::make_temp_dir("atomic");
  auto target = dir / "out.txt";
  { std::ofstream(target) << "old"; }
  write_file_atomically(target, [](std::ostream& os) { os << "new content"; });
  EXPECT_EQ(slurp(target), "new content");
  int files = 0;
  for ([[maybe_unused]] auto& e : std::filesystem::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1);
  std::filesystem::remove_all(dir);
}

TEST(AtomicFileTest, FailedWriteLeavesOldTargetUntouched) {
  auto dir = test::make_temp_dir("atomic");
  auto target = dir / "out.txt";
  { std::ofstream(target) << "old"; }
  EXPECT_THROW(write_file_atomically(target,
                                     [](std::ostream& os) {
                                       os << "half";
                                       throw std::runtime_error("writer failed");
                                     }),
               std::runtime_error);
  EXPECT_EQ(slurp(target), "old");
  int files = 0;
  for ([[maybe_unused]] auto& e : std::filesystem::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1) << "the temporary file must be removed";
  std::filesystem::remove_all(dir);
}

TEST(AtomicFileTest, UnwritableFolderGivesIoError) {
  EXPECT_THROW(AtomicFile("/nonexistent-folder/x/y.ply"), IoError);
}

TEST(ErrorsTest, ExitCodesByType) {
  EXPECT_EQ(exit_code_for(InputError("f.ply", "line 3", "expected 3 numbers")),
            ExitCode::kBadInput);
  EXPECT_EQ(exit_code_for(OptionError("h must be > 0")), ExitCode::kBadOptions);
  EXPECT_EQ(exit_code_for(IoError("disk full")), ExitCode::kIoFailure);
  EXPECT_EQ(exit_code_for(UnavailableError("no device")), ExitCode::kUnavailable);
  EXPECT_EQ(exit_code_for(std::runtime_error("x")), ExitCode::kFailure);
  EXPECT_STREQ(InputError("f.ply", "line 3", "expected 3 numbers").what(),
               "f.ply: line 3: expected 3 numbers");
}

TEST(AtomicFileTest, CommitGroupCommitsAllOrNothing) {
  auto dir = test::make_temp_dir("atomic");
  {  // the second write fails: the first target must not change (a cloud and its outliers)
    { std::ofstream(dir / "a.txt") << "old a"; }
    AtomicCommitGroup group;
    write_file_atomically(dir / "a.txt", [](std::ostream& os) { os << "new a"; });
    EXPECT_EQ(slurp(dir / "a.txt"), "old a") << "renamed before the group committed";
    EXPECT_THROW(write_file_atomically(dir / "b.txt",
                                       [](std::ostream&) { throw std::runtime_error("full"); }),
                 std::runtime_error);
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "old a");
  EXPECT_FALSE(std::filesystem::exists(dir / "b.txt"));
  {
    AtomicCommitGroup group;
    write_file_atomically(dir / "a.txt", [](std::ostream& os) { os << "new a"; });
    write_file_atomically(dir / "b.txt", [](std::ostream& os) { os << "new b"; });
    group.commit();
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "new a");
  EXPECT_EQ(slurp(dir / "b.txt"), "new b");
  int files = 0;
  for ([[maybe_unused]] auto& e : std::filesystem::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 2) << "temporary files left behind";
  std::filesystem::remove_all(dir);
}

TEST(AtomicFileTest, TemporariesOfKilledProcessesAreRemoved) {
  auto dir = test::make_temp_dir("atomic");
  // pid 999999999 is above any Linux pid_max: that process is gone.
  const auto stale = dir / ".out.ply.tmp.999999999.0";
  const auto other = dir / "notes.tmp.txt";  // not a temporary of ours
  { std::ofstream(stale) << "half a cloud"; }
  { std::ofstream(other) << "keep"; }
  const std::size_t before = stale_temporaries_removed();
  write_file_atomically(dir / "x.txt", [](std::ostream& os) { os << "x"; });
  EXPECT_FALSE(std::filesystem::exists(stale));
  EXPECT_TRUE(std::filesystem::exists(other));
  EXPECT_EQ(stale_temporaries_removed(), before + 1);
  std::filesystem::remove_all(dir);
}

TEST(AtomicFileTest, MissingFolderIsNamed) {
  auto dir = test::make_temp_dir("atomic");
  try {
    AtomicFile f(dir / "no_such_folder" / "out.ply");
    FAIL() << "no error";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_folder\" does not exist"), std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace scanclean
