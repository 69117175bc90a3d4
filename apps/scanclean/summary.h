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

}  // namespace scanclean::app
