#pragma once
//! Subcommand registry of the scanclean program. Each cmd_<name>.cpp defines one subcommand:
//!
//!   static scanclean::app::CommandRegistrar reg{{"info", "Describe point-cloud files", 10,
//!     [](CLI::App& cmd) { auto opts = std::make_shared<...>(); cmd.add_option(...);
//!                          return [opts] { ...; return 0; }; }}};
//!
//! The setup function adds its options to the subcommand and returns the action that runs after
//! parsing. Actions return an exit code, or throw one of scanclean's typed exceptions, which
//! main() reports and maps to the documented exit codes (core/errors.h).

#include <CLI/CLI.hpp>
#include <functional>
#include <string>
#include <vector>

namespace scanclean::app {

using Action = std::function<int()>;

struct Command {
  std::string name;
  std::string description;
  int order = 100;  //!< position in --help
  std::function<Action(CLI::App&)> setup;
};

std::vector<Command>& command_registry();

//! Option checks with readable messages ("expected a number > 0, got -1"), replacing CLI11's
//! PositiveNumber / NonNegativeNumber, whose message prints the double range in full.
const CLI::Validator& positive_number();
const CLI::Validator& non_negative_number();
//! A number in [lo, hi] ((lo, hi] with lo_open): "expected a number in (0, 20], got 25".
CLI::Validator number_in(double lo, double hi, bool lo_open = false);
//! An integer in [lo, hi]: "expected an integer in [1, 2], got 3".
CLI::Validator integer_in(long long lo, long long hi);

struct CommandRegistrar {
  explicit CommandRegistrar(Command c) { command_registry().push_back(std::move(c)); }
};

}  // namespace scanclean::app
