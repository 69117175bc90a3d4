#include "scanclean/provenance.h"

#include <cstdio>

namespace scanclean::app {

const char* const kScancleanVersion = SCANCLEAN_VERSION;

namespace {

std::string& kept_command_line() {
  static std::string line;
  return line;
}

std::string metres(double v) {
  char b[48];
  std::snprintf(b, sizeof b, "%.6g m", v);
  return b;
}

}  // namespace

void set_command_line(int argc, char** argv, const char* program) {
  std::string line;
  for (int i = 0; i < argc; ++i) {
    std::string a = i == 0 ? std::string(program) : std::string(argv[i]);
    const bool quote = a.empty() || a.find_first_of(" \t'\"") != std::string::npos;
    if (!line.empty()) line += ' ';
    line += quote ? "'" + a + "'" : a;
  }
  kept_command_line() = line;
}

const std::string& command_line() {
  return kept_command_line();
}

std::string provenance_text(double h, double noise_sigma) {
  std::string text;
  if (h > 0) text += "h=" + metres(h) + ", ";
  if (noise_sigma > 0) text += "noise_sigma=" + metres(noise_sigma) + ", ";
  return text + "command: " + command_line();
}

}  // namespace scanclean::app
