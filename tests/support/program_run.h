#pragma once
//! Runs the scanclean program as a user would, for the end-to-end tests: arguments passed
//! without shell expansion, stdin from /dev/null, stdout and stderr captured.

#include <filesystem>
#include <string>
#include <vector>

namespace scanclean::test {

struct ProgramRun {
  int exit_code = -1;  //!< the exit status (124 when the time limit killed it)
  std::string out, err;
};

//! Runs `program` with `args`; its stdout and stderr go through files in `dir`. limit_s > 0:
//! killed after that many seconds (exit 124, as timeout(1) reports it).
ProgramRun run_program(const std::string& program, const std::vector<std::string>& args,
                       const std::filesystem::path& dir, int limit_s = 0);

//! The whole content of a file ("" if it cannot be read).
std::string slurp(const std::filesystem::path& file);

}  // namespace scanclean::test
