#include "support/data_paths.h"

#include <unistd.h>

#include <atomic>
#include <cstdlib>

namespace scanclean::test {

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
  if (const auto* info = ::testing::UnitTest::GetInstance()->current_test_info())
    name += std::string("_") + info->name();
  auto dir = std::filesystem::temp_directory_path() / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace scanclean::test
