#pragma once
//! The one-screen summary every long command prints at the end (to stdout), as aligned
//! "key: value" lines under a title.

#include <string>
#include <utility>
#include <vector>

namespace scanclean::app {

class Summary {
 public:
  explicit Summary(std::string title) : title_(std::move(title)) {}
  Summary& add(std::string key, std::string value);
  Summary& add(std::string key, double value, int precision = 3, const std::string& unit = "");
  Summary& add_count(std::string key, unsigned long long value);
  void print() const;  //!< to stdout

 private:
  std::string title_;
  std::vector<std::pair<std::string, std::string>> rows_;
};

//! "1,234,567"
std::string with_thousands(unsigned long long value);

}  // namespace scanclean::app
