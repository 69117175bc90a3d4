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

}  // namespace
}  // namespace scanclean
