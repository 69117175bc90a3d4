#include "report.h"

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <sstream>
#include <thread>

#ifndef SCANCLEAN_SOURCE_DIR
#define SCANCLEAN_SOURCE_DIR "."
#endif

namespace scanclean::bench {

std::string Table::markdown() const {
  std::ostringstream s;
  s << "### " << title << "\n\n|";
  for (const auto& h : header) s << " " << h << " |";
  s << "\n|";
  for (std::size_t i = 0; i < header.size(); ++i) s << (i == 0 ? " --- |" : " ---: |");
  s << "\n";
  for (const auto& r : rows) {
    s << "|";
    for (const auto& c : r) s << " " << c << " |";
    s << "\n";
  }
  if (!notes.empty()) {
    s << "\n";
    for (const auto& n : notes) s << "- " << n << "\n";
  }
  s << "\n";
  return s.str();
}

std::string fmt(double v, int precision) {
  if (std::isnan(v)) return "-";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", precision, v);
  return buf;
}

std::string fmt_pct(double fraction, int precision) {
  if (std::isnan(fraction)) return "-";
  return fmt(100.0 * fraction, precision) + " %";
}

std::string fmt_count(std::size_t n) {
  std::string d = std::to_string(n);
  std::string out;
  for (std::size_t i = 0; i < d.size(); ++i) {
    if (i > 0 && (d.size() - i) % 3 == 0) out += ',';
    out += d[i];
  }
  return out;
}

namespace {
std::string run_command(const std::string& cmd) {
  std::string out;
  FILE* p = popen(cmd.c_str(), "r");
  if (p == nullptr) return out;
  std::array<char, 256> buf{};
  while (std::fgets(buf.data(), buf.size(), p) != nullptr) out += buf.data();
  pclose(p);
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

std::size_t status_kb(const std::string& key) {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind(key + ":", 0) == 0) {
      std::istringstream s(line.substr(key.size() + 1));
      std::size_t kb = 0;
      s >> kb;
      return kb;
    }
  }
  return 0;
}
}  // namespace

MachineInfo machine_info() {
  MachineInfo m;
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) m.cpu_model = line.substr(colon + 2);
      break;
    }
  }
  if (m.cpu_model.empty()) m.cpu_model = "unknown";
  m.cores = std::thread::hardware_concurrency();
  const std::string git = std::string("git -C '") + SCANCLEAN_SOURCE_DIR + "' ";
  m.commit = run_command(git + "rev-parse --short=12 HEAD 2>/dev/null");
  if (m.commit.empty()) m.commit = "unknown";
  if (!run_command(git + "status --porcelain --untracked-files=no 2>/dev/null").empty())
    m.commit += "+dirty";
  const std::time_t now = std::time(nullptr);
  char buf[64];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S UTC", std::gmtime(&now));
  m.date_utc = buf;
#if defined(__clang__)
  m.compiler = "clang " __clang_version__;
#elif defined(__GNUC__)
  m.compiler = "gcc " __VERSION__;
#else
  m.compiler = "unknown";
#endif
  return m;
}

std::size_t current_rss_bytes() {
  return status_kb("VmRSS") * 1024;
}
std::size_t peak_rss_bytes() {
  return status_kb("VmHWM") * 1024;
}
bool reset_peak_rss() {
  std::ofstream f("/proc/self/clear_refs");
  if (!f) return false;
  f << "5";
  f.flush();
  return static_cast<bool>(f);
}

}  // namespace scanclean::bench
