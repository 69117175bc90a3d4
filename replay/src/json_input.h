#pragma once
//! \file json_input.h (private to scanclean::replay)
//! Parses the JSON files of recordings and depth-image folders (session.json, intrinsics.json)
//! as untrusted input: every failure of the parser (syntax, a number out of the double range
//! such as 1e400, invalid UTF-8) is an InputError naming the file, the byte and, for a number,
//! the key it belongs to.

#include <nlohmann/json.hpp>
#include <string>

namespace scanclean::detail {

//! \throw InputError "<file>: byte N: ..." or "<file>: key \"fx\": number 1e400 out of range".
nlohmann::json parse_json_input(const std::string& text, const std::string& file);

}  // namespace scanclean::detail
