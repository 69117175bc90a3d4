#include "support/data_paths.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <mutex>
#include <system_error>
#include <vector>

namespace scanclean::test {
namespace {

// The folders make_temp_dir made, removed when the test program ends: by the process that made
// them (a forked child that exits leaves them alone), and only when every test passed (a failed
// test's files stay for inspection) and SCANCLEAN_KEEP_TEST_DIRS is not set.
class MadeDirs {
 public:
  void add(const std::filesystem::path& dir) {
    const std::lock_guard<std::mutex> lock(mutex_);
    dirs_.push_back(dir);
  }
  ~MadeDirs() {
    if (::getpid() != owner_ || std::getenv("SCANCLEAN_KEEP_TEST_DIRS") != nullptr) return;
    if (::testing::UnitTest::GetInstance()->Failed()) return;
    for (const auto& dir : dirs_) {
      std::error_code ec;  // a folder a test removed itself, or cannot be removed: left alone
      std::filesystem::remove_all(dir, ec);
    }
  }

 private:
  std::mutex mutex_;
  std::vector<std::filesystem::path> dirs_;
  pid_t owner_ = ::getpid();
};

MadeDirs& made_dirs() {
  static MadeDirs dirs;
  return dirs;
}

}  // namespace

std::filesystem::path shared_data_dir() {
  if (const char* env = std::getenv("SCANCLEAN_SHARED_DATA")) return env;
  return SCANCLEAN_SHARED_DATA_DIR;
}

std::filesystem::path recordings_dir() {
  return SCANCLEAN_RECORDINGS_DIR;
}

std::filesystem::path binary_dir() {
  return SCANCLEAN_BINARY_DIR;
}

std::filesystem::path make_temp_dir(const std::string& tag) {
  static std::atomic<int> counter{0};
  std::string name =
      "scanclean_test_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
  if (const auto* info = ::testing::UnitTest::GetInstance()->current_test_info()) {
    std::string test = info->name();  // "Name/0" for a parameterised test: one folder, not two
    std::replace(test.begin(), test.end(), '/', '_');
    name += "_" + test;
  }
  auto dir = std::filesystem::temp_directory_path() / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  made_dirs().add(dir);
  return dir;
}

}  // namespace scanclean::test
