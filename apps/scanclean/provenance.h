#pragma once
//! Provenance of the files the program writes: the command line of this run (kept by main()) and
//! the header comment text (WriteOptions::provenance) that records it with the filter's h and
//! noise sigma, e.g. "h=0.00213 m, noise_sigma=0.00031 m, command: scanclean filter in.ply -o
//! out.ply". The version is written by the io writers themselves ("written by scanclean 0.1.0").
//! The "h=... m" form is the one `scanclean mesh` reads back (recorded_kernel_size).

#include <string>

namespace scanclean::app {

//! The program's version, "0.1.0".
extern const char* const kScancleanVersion;

//! Keeps this run's command line (arguments joined by spaces, quoted when they hold a space),
//! the program named `program` (argv[0] is a path).
void set_command_line(int argc, char** argv, const char* program = "scanclean");

//! The command line kept by set_command_line ("" before).
const std::string& command_line();

//! "command: <command line>"; with h > 0 prefixed by "h=<h> m, " and with noise_sigma > 0 by
//! "noise_sigma=<sigma> m, " (metres, 6 significant digits).
std::string provenance_text(double h = 0, double noise_sigma = 0);

}  // namespace scanclean::app
