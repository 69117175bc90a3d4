#pragma once
//! The malformed-input corpus (tests/data/malformed): every file with the error it must give,
//! read from EXPECTED.tsv ("file<TAB>InputError|IoError|OptionError<TAB>message fragment").

#include <exception>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "scanclean/core/errors.h"

namespace scanclean::test {

struct MalformedCase {
  std::string file, type, fragment;
};

inline std::filesystem::path malformed_dir() {
  return std::filesystem::path(SCANCLEAN_SOURCE_DIR) / "tests" / "data" / "malformed";
}

//! The cases whose file name starts with one of `prefixes`.
inline std::vector<MalformedCase> malformed_cases(const std::vector<std::string>& prefixes) {
  std::vector<MalformedCase> out;
  std::ifstream in(malformed_dir() / "EXPECTED.tsv");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const auto a = line.find('\t'), b = line.find('\t', a + 1);
    if (a == std::string::npos || b == std::string::npos) continue;
    MalformedCase c{line.substr(0, a), line.substr(a + 1, b - a - 1), line.substr(b + 1)};
    for (const auto& p : prefixes)
      if (c.file.rfind(p, 0) == 0) out.push_back(c);
  }
  return out;
}

//! The name of the scanclean exception type of `e` ("" for any other exception).
inline std::string error_type(const std::exception& e) {
  if (dynamic_cast<const InputError*>(&e)) return "InputError";
  if (dynamic_cast<const IoError*>(&e)) return "IoError";
  if (dynamic_cast<const OptionError*>(&e)) return "OptionError";
  if (dynamic_cast<const UnavailableError*>(&e)) return "UnavailableError";
  return "";
}

}  // namespace scanclean::test
