// scanclean: robust filtering of noisy scanner output (Schall, Belyaev, Seidel 2005) and the
// acquisition pipeline around it. This file only wires the subcommands together.

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <exception>
#include <string>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/process_memory.h"
#include "scanclean/run_report.h"

namespace {

constexpr const char* kExitCodes =
    "Exit codes: 0 ok, 1 internal error, 2 bad command line or option, 3 bad input data,\n"
    "4 file I/O failure, 5 device/driver/feature unavailable, 6 empty or collapsed result\n"
    "(0 or 1 point out of more; nothing written), 130 interrupted.";

}  // namespace

int main(int argc, char** argv) {
  using scanclean::ExitCode;
  scanclean::keep_freed_arrays_for_reuse();  // before any allocation worth keeping
  CLI::App app{
      "scanclean: turns noisy scanner output into clean surface points.\n"
      "Robust filter of Schall, Belyaev and Seidel (2005) with OpenNI2, recording and\n"
      "structured-light sources. Units are metres unless stated otherwise.",
      "scanclean"};
  app.footer(kExitCodes);
  app.require_subcommand(1);
  app.set_version_flag("--version", "scanclean 0.1.0");

  auto& registry = scanclean::app::command_registry();
  std::stable_sort(registry.begin(), registry.end(),
                   [](const auto& a, const auto& b) { return a.order < b.order; });
  scanclean::app::Action selected;
  for (auto& command : registry) {
    CLI::App* sub = app.add_subcommand(command.name, command.description);
    sub->footer(kExitCodes);
    auto action = std::make_shared<scanclean::app::Action>(command.setup(*sub));
    sub->callback([action, &selected] { selected = *action; });
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints help or the parse error
    return rc == 0 ? 0 : static_cast<int>(ExitCode::kBadOptions);
  }

  int rc = 0;
  std::string error;
  try {
    scanclean::app::begin_report(app, argc, argv);  // --report: checked before any work
    rc = selected ? selected() : static_cast<int>(ExitCode::kBadOptions);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scanclean: error: %s\n", e.what());
    rc = static_cast<int>(scanclean::exit_code_for(e));
    error = e.what();
  }
  if (!scanclean::app::end_report(rc, error) && rc == 0)
    rc = static_cast<int>(ExitCode::kIoFailure);
  return rc;
}
