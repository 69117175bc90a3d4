#include "scanclean/command.h"

#include <cmath>

namespace scanclean::app {

std::vector<Command>& command_registry() {
  static std::vector<Command> registry;
  return registry;
}

namespace {

CLI::Validator number_check(bool allow_zero) {
  const std::string expected = allow_zero ? "a number >= 0" : "a number > 0";
  return CLI::Validator(
      [allow_zero, expected](std::string& text) -> std::string {
        double value = 0;
        if (!CLI::detail::lexical_cast(text, value) || !std::isfinite(value))
          return "expected " + expected + ", got '" + text + "'";
        if (value < 0 || (!allow_zero && value == 0))
          return "expected " + expected + ", got " + text;
        return {};
      },
      allow_zero ? "NONNEGATIVE" : "POSITIVE");
}

}  // namespace

const CLI::Validator& positive_number() {
  static const CLI::Validator check = number_check(false);
  return check;
}

const CLI::Validator& non_negative_number() {
  static const CLI::Validator check = number_check(true);
  return check;
}

}  // namespace scanclean::app
