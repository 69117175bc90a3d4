#include "scanclean/command.h"

#include <cmath>
#include <sstream>

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

std::string number_text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace

CLI::Validator number_in(double lo, double hi, bool lo_open) {
  const std::string expected = "a number in " + std::string(lo_open ? "(" : "[") + number_text(lo) +
                               ", " + number_text(hi) + "]";
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        double value = 0;
        if (!CLI::detail::lexical_cast(text, value) || !std::isfinite(value))
          return "expected " + expected + ", got '" + text + "'";
        if ((lo_open ? value <= lo : value < lo) || value > hi)
          return "expected " + expected + ", got " + text;
        return {};
      },
      "NUMBER");
}

CLI::Validator integer_in(long long lo, long long hi) {
  const std::string expected =
      "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        long long value = 0;
        if (!CLI::detail::lexical_cast(text, value))
          return "expected " + expected + ", got '" + text + "'";
        if (value < lo || value > hi) return "expected " + expected + ", got " + text;
        return {};
      },
      "INT");
}

const CLI::Validator& positive_number() {
  static const CLI::Validator check = number_check(false);
  return check;
}

const CLI::Validator& non_negative_number() {
  static const CLI::Validator check = number_check(true);
  return check;
}

}  // namespace scanclean::app
