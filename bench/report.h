#pragma once
//! \file report.h
//! Tables (printed to stdout as they are completed, and collected for the Markdown report) and
//! facts about the machine for the report header.

#include <cstddef>
#include <string>
#include <vector>

namespace scanclean::bench {

struct Table {
  std::string title;
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> notes;  //!< printed under the table
  std::string markdown() const;
};

//! Number formatting helpers ("-" for NaN).
std::string fmt(double v, int precision = 3);
std::string fmt_pct(double fraction, int precision = 2);  //!< "99.50 %"
std::string fmt_count(std::size_t n);                     //!< "1,234,567"

struct MachineInfo {
  std::string cpu_model;
  unsigned cores = 0;
  std::string commit;  //!< scanclean commit (and "+dirty" when the tree has changes)
  std::string date_utc;
  std::string compiler;
};
MachineInfo machine_info();

//! Resident memory of this process (Linux /proc/self/status): current and peak, in bytes.
std::size_t current_rss_bytes();
std::size_t peak_rss_bytes();
//! Resets the peak (writes 5 to /proc/self/clear_refs); false if the kernel refused.
bool reset_peak_rss();

}  // namespace scanclean::bench
