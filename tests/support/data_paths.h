#pragma once
//! Locations of test data. The shared real scans live beside the repository (../shared/data);
//! a fresh clone without them still builds, and tests that need them skip with a clear message.

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace scanclean::test {

//! ../shared/data (or $SCANCLEAN_SHARED_DATA); may not exist.
std::filesystem::path shared_data_dir();
//! The repository's recordings/ folder (always present).
std::filesystem::path recordings_dir();
//! The build tree (for the private OpenNI2 driver folder, <build>/oni).
std::filesystem::path binary_dir();
//! A fresh, empty temporary folder unique to the running test, under the system temp dir. The
//! caller may remove it; what is left is removed when the test program ends, unless a test
//! failed or SCANCLEAN_KEEP_TEST_DIRS is set.
std::filesystem::path make_temp_dir(const std::string& tag);

}  // namespace scanclean::test

//! Skips the current test, with a message naming the missing path, when a shared-data file or
//! folder is absent. Use at the top of a test body.
#define SCANCLEAN_REQUIRE_SHARED(relpath)                                                  \
  do {                                                                                     \
    if (!std::filesystem::exists(::scanclean::test::shared_data_dir() / (relpath)))        \
      GTEST_SKIP() << "shared data not available: "                                        \
                   << (::scanclean::test::shared_data_dir() / (relpath)).string()          \
                   << " (clone the repository with ../shared beside it to run this test)"; \
  } while (0)
