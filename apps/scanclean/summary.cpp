#include "scanclean/summary.h"

#include <cstdio>
#include <iomanip>
#include <sstream>

#include "scanclean/run_report.h"

namespace scanclean::app {

Summary& Summary::add(std::string key, std::string value) {
  rows_.push_back({std::move(key), std::move(value), std::nullopt, {}, false});
  return *this;
}

Summary& Summary::add(std::string key, double value, int precision, const std::string& unit) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(precision) << value;
  if (!unit.empty()) os << ' ' << unit;
  rows_.push_back({std::move(key), os.str(), value, unit, false});
  return *this;
}

Summary& Summary::add_count(std::string key, unsigned long long value) {
  rows_.push_back({std::move(key), with_thousands(value), static_cast<double>(value), {}, true});
  return *this;
}

void Summary::print() const {
  std::size_t width = 0;
  for (const auto& r : rows_) width = std::max(width, r.key.size());
  std::printf("%s\n", title_.c_str());
  for (const auto& r : rows_)
    std::printf("  %-*s  %s\n", static_cast<int>(width + 1), (r.key + ":").c_str(), r.text.c_str());
  std::fflush(stdout);
  note_report_summary(title_, rows_);
}

void warn_if_mostly_unsupported(unsigned long long unsupported, unsigned long long points_in,
                                double h) {
  if (points_in == 0 || unsupported * 2 <= points_in) return;
  std::fprintf(stderr,
               "scanclean: warning: %s of %s points (%.0f %%) had no kernel support within h = "
               "%.4g mm and were removed as unsupported; if the cloud is a surface, h is too "
               "small for its spacing or noise (give a larger --h or --k, or the automatic "
               "scale)\n",
               with_thousands(unsupported).c_str(), with_thousands(points_in).c_str(),
               100.0 * static_cast<double>(unsupported) / static_cast<double>(points_in),
               h * 1000.0);
}

void warn_dropped_invalid(const std::string& file, unsigned long long dropped) {
  if (dropped == 0) return;
  std::fprintf(stderr,
               "scanclean: %s: %s invalid points dropped while reading (x, y or z not finite)\n",
               file.c_str(), with_thousands(dropped).c_str());
}

std::string with_thousands(unsigned long long value) {
  std::string s = std::to_string(value);
  for (int i = static_cast<int>(s.size()) - 3; i > 0; i -= 3)
    s.insert(static_cast<std::size_t>(i), ",");
  return s;
}

}  // namespace scanclean::app
