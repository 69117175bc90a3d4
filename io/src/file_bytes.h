#pragma once
// Internal: whole-file reading and small parsing helpers shared by the readers.

#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>

namespace scanclean::io_detail {

//! The whole file. \throw IoError if it cannot be opened or read.
std::string read_file_bytes(const std::filesystem::path& path);

//! Parses a complete token as a double ("nan", "inf" accepted; a leading '+' too).
inline std::optional<double> parse_double(std::string_view s) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  double v = 0;
  auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (r.ec != std::errc() || r.ptr != s.data() + s.size()) {
    if (r.ec == std::errc::result_out_of_range && r.ptr == s.data() + s.size())
      return (!s.empty() && s.front() == '-') ? -HUGE_VAL : HUGE_VAL;
    return std::nullopt;
  }
  return v;
}

//! Parses a complete token as a signed 64-bit integer.
inline std::optional<std::int64_t> parse_int(std::string_view s) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  std::int64_t v = 0;
  auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (r.ec != std::errc() || r.ptr != s.data() + s.size()) return std::nullopt;
  return v;
}

//! Splits off the next whitespace-separated token of `line` (spaces, tabs, '\r').
inline std::string_view next_token(std::string_view& line) {
  std::size_t b = 0;
  while (b < line.size() && (line[b] == ' ' || line[b] == '\t' || line[b] == '\r')) ++b;
  std::size_t e = b;
  while (e < line.size() && line[e] != ' ' && line[e] != '\t' && line[e] != '\r') ++e;
  std::string_view tok = line.substr(b, e - b);
  line.remove_prefix(e);
  return tok;
}

//! Quotes a header/token excerpt for an error message (at most 60 characters, printable).
std::string quote(std::string_view s);

//! The shortest text that reads back to exactly this value.
std::string format_double(double v);
std::string format_float(float v);

}  // namespace scanclean::io_detail
