#pragma once
// Internal: text for a one-line header comment (PLY `comment`, PCD `#`), e.g. the provenance.

#include <string>

namespace scanclean::io_detail {

//! `text` with every control character (newlines included) replaced by a space, so that it can
//! neither end the comment line nor inject header lines.
inline std::string header_comment_text(std::string text) {
  for (char& c : text)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = ' ';
  return text;
}

}  // namespace scanclean::io_detail
