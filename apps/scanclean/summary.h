#pragma once
//! The one-screen summary every long command prints at the end (to stdout), as aligned
//! "key: value" lines under a title.

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace scanclean::app {

//! One printed line: the key, the text shown, and for numbers their value (unrounded) and unit.
struct SummaryRow {
  std::string key;
  std::string text;
  std::optional<double> value;
  std::string unit;
  bool count = false;  //!< value is a count (an integer)
};

class Summary {
 public:
  explicit Summary(std::string title) : title_(std::move(title)) {}
  Summary& add(std::string key, std::string value);
  Summary& add(std::string key, double value, int precision = 3, const std::string& unit = "");
  Summary& add_count(std::string key, unsigned long long value);
  //! To stdout; also hands the lines to the run's --report, if any (run_report.h).
  void print() const;

 private:
  std::string title_;
  std::vector<SummaryRow> rows_;
};

//! "1,234,567"
std::string with_thousands(unsigned long long value);

//! After the summary of a filter run: a warning on stderr when more than half of the points_in
//! had no kernel within h (metres) and were removed as unsupported. The output is then what the
//! kernels reached, not the cloud's surface (h far too small for the cloud, or a cloud that is
//! mostly scattered points); it is written, since it may be what was asked for.
void warn_if_mostly_unsupported(unsigned long long unsupported, unsigned long long points_in,
                                double h);

//! When a reader dropped points whose x, y or z was not finite (NaN marks a missing pixel in
//! many scanners' files): one line on stderr naming the file and the count. Nothing when 0.
void warn_dropped_invalid(const std::string& file, unsigned long long dropped);

}  // namespace scanclean::app
