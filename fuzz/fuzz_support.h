#pragma once
//! Shared by the fuzz targets: a private temporary folder per process (in /dev/shm when it
//! exists) and the rule for exceptions. The readers' contract is that malformed input gives one
//! of scanclean's typed exceptions (InputError, IoError, OptionError); any other exception is a
//! finding, so it is left to escape and libFuzzer reports it as a crash.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

namespace scanclean::fuzz {

//! This process's temporary folder (created once, removed at exit).
const std::filesystem::path& temp_dir();

//! Writes `size` bytes to temp_dir()/name and returns the path.
std::filesystem::path write_input(const std::string& name, const std::uint8_t* data,
                                  std::size_t size);

}  // namespace scanclean::fuzz

//! Runs `body`; swallows scanclean::Error (the expected answer to a malformed file).
#define SCANCLEAN_FUZZ_EXPECTED_ERRORS(body) \
  try {                                      \
    body;                                    \
  } catch (const scanclean::Error&) {        \
  }
