#include "scanclean/summary.h"

#include <cstdio>
#include <iomanip>
#include <sstream>

namespace scanclean::app {

Summary& Summary::add(std::string key, std::string value) {
  rows_.emplace_back(std::move(key), std::move(value));
  return *this;
}

Summary& Summary::add(std::string key, double value, int precision, const std::string& unit) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(precision) << value;
  if (!unit.empty()) os << ' ' << unit;
  return add(std::move(key), os.str());
}

Summary& Summary::add_count(std::string key, unsigned long long value) {
  return add(std::move(key), with_thousands(value));
}

void Summary::print() const {
  std::size_t width = 0;
  for (const auto& r : rows_) width = std::max(width, r.first.size());
  std::printf("%s\n", title_.c_str());
  for (const auto& r : rows_)
    std::printf("  %-*s  %s\n", static_cast<int>(width + 1), (r.first + ":").c_str(),
                r.second.c_str());
  std::fflush(stdout);
}

std::string with_thousands(unsigned long long value) {
  std::string s = std::to_string(value);
  for (int i = static_cast<int>(s.size()) - 3; i > 0; i -= 3)
    s.insert(static_cast<std::size_t>(i), ",");
  return s;
}

}  // namespace scanclean::app
