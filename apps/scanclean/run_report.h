#pragma once
//! The machine-readable report of one run (`--report FILE.json`), added once for every command
//! that computes. A command opts in with add_report_option() in its setup; main() begins the
//! report after parsing (the path is checked then, before any work) and ends it with the exit
//! code. The rest is gathered through hooks in the shared rooms: the summary (summary.h) hands
//! over every line it prints, the path checks (output_checks.h) the input and output files, and
//! the commands that run the filter its statistics. The JSON holds: version, command, command
//! line, the options in force (as typed, or their defaults), input and output files with their
//! sizes and SHA-256, every summary, the filter statistics, timings, exit code and error. It is
//! written atomically, also when the command fails after the report was begun.

#include <CLI/CLI.hpp>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "scanclean/output_checks.h"
#include "scanclean/summary.h"

namespace scanclean {
struct FilterStats;
}

namespace scanclean::app {

//! Adds --report FILE.json to `cmd`.
void add_report_option(CLI::App& cmd);

//! After parsing: when the parsed (deepest) subcommand of `app` was given --report, starts the
//! report (clock, command line, options in force) and checks its path (.json, existing
//! writable folder, not a folder). \throw OptionError, IoError.
void begin_report(CLI::App& app, int argc, char** argv);

//! Writes the report (when one was begun) with the exit code and the error message ("" = none).
//! Returns false (after a message on stderr) when it could not be written.
bool end_report(int exit_code, const std::string& error);

//! The report's path while a report is being made.
std::optional<std::filesystem::path> report_path();

//! Hooks: an input (file or folder; folders are listed file by file) and an output file of the
//! run. Outputs that exist when the report is written get their size and hash. No-ops without a
//! report.
void note_report_input(const PathArg& input);
void note_report_output(const PathArg& output);

//! Hook of Summary::print(): one printed summary.
void note_report_summary(const std::string& title, const std::vector<SummaryRow>& rows);

//! Hook of the commands that run the filter: its statistics for one output (`label`, e.g. the
//! output file).
void note_report_filter(const std::string& label, const FilterStats& stats);

//! Lower-case hex SHA-256 of a file's bytes (OpenSSL's libcrypto). \throw IoError naming it.
std::string sha256_of_file(const std::filesystem::path& file);

}  // namespace scanclean::app
