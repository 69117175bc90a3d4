#include "scanclean/core/errors.h"

namespace scanclean {

InputError::InputError(const std::string& file, const std::string& place, const std::string& what)
    : Error(file + ": " + (place.empty() ? std::string() : place + ": ") + what) {}

ExitCode exit_code_for(const std::exception& e) noexcept {
  if (dynamic_cast<const OptionError*>(&e)) return ExitCode::kBadOptions;
  if (dynamic_cast<const InputError*>(&e)) return ExitCode::kBadInput;
  if (dynamic_cast<const IoError*>(&e)) return ExitCode::kIoFailure;
  if (dynamic_cast<const UnavailableError*>(&e)) return ExitCode::kUnavailable;
  return ExitCode::kFailure;
}

std::string byte_place(std::uint64_t offset) {
  return "byte " + std::to_string(offset);
}
std::string line_place(std::uint64_t line) {
  return "line " + std::to_string(line);
}

}  // namespace scanclean
