#include "scanclean/run_report.h"

#include <openssl/evp.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <system_error>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/provenance.h"
#if defined(SCANCLEAN_HAVE_FILTER)
#include "scanclean/filter/robust_filter.h"
#endif

namespace scanclean::app {

namespace fs = std::filesystem;
using nlohmann::ordered_json;

namespace {

using Clock = std::chrono::steady_clock;

struct ReportState {
  fs::path path;
  std::string command;
  std::vector<std::string> argv;
  std::string started_utc;
  Clock::time_point start;
  ordered_json options = ordered_json::object();
  std::vector<std::string> options_given;
  std::vector<PathArg> inputs, outputs;
  ordered_json summaries = ordered_json::array();
  ordered_json filter_runs = ordered_json::array();
};

std::unique_ptr<ReportState>& state() {
  static std::unique_ptr<ReportState> s;
  return s;
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// A file's size and hash, or a folder's files (sorted, recursively), each with both.
ordered_json describe_path(const PathArg& a) {
  ordered_json j;
  j["option"] = a.option;
  j["path"] = a.path.string();
  std::error_code ec;
  if (fs::is_regular_file(a.path, ec)) {
    j["bytes"] = static_cast<std::uint64_t>(fs::file_size(a.path, ec));
    j["sha256"] = sha256_of_file(a.path);
  } else if (fs::is_directory(a.path, ec)) {
    std::vector<fs::path> files;
    for (fs::recursive_directory_iterator it(a.path, ec), end; !ec && it != end; it.increment(ec))
      if (it->is_regular_file(ec)) files.push_back(it->path());
    std::sort(files.begin(), files.end());
    ordered_json list = ordered_json::array();
    std::uint64_t total = 0;
    for (const auto& f : files) {
      const auto bytes = static_cast<std::uint64_t>(fs::file_size(f, ec));
      total += bytes;
      list.push_back({{"path", fs::relative(f, a.path, ec).string()},
                      {"bytes", bytes},
                      {"sha256", sha256_of_file(f)}});
    }
    j["bytes"] = total;
    j["files"] = std::move(list);
  } else {
    j["exists"] = false;  // e.g. a device URI, or an output not written
  }
  return j;
}

ordered_json summary_json(const std::string& title, const std::vector<SummaryRow>& rows) {
  ordered_json lines = ordered_json::object();
  for (const auto& r : rows) {
    std::string key = r.key;
    for (int n = 2; lines.contains(key); ++n) key = r.key + " #" + std::to_string(n);
    ordered_json line;
    line["text"] = r.text;
    if (r.value) {
      if (r.count)
        line["value"] = static_cast<std::uint64_t>(*r.value);
      else
        line["value"] = *r.value;
      if (!r.unit.empty()) line["unit"] = r.unit;
    }
    lines[key] = std::move(line);
  }
  return {{"title", title}, {"lines", std::move(lines)}};
}

// The value of an option as it is in force: the values typed, or the default (what the bound
// variable holds after parsing).
ordered_json option_value(CLI::Option* opt) {
  if (opt->get_expected_max() == 0) return opt->count() > 0;  // a flag
  if (opt->count() > 0) {
    const auto& res = opt->results();
    if (res.size() == 1) return res.front();
    return res;
  }
  opt->capture_default_str();
  return opt->get_default_str();
}

}  // namespace

void add_report_option(CLI::App& cmd) {
  cmd.add_option("--report",
                 "Also write a JSON report of the run: version, command line, options "
                 "in force, input and output files (bytes, SHA-256), the summary's "
                 "figures, the filter statistics, timings, exit code (written "
                 "atomically, also when the run fails)")
      ->type_name("FILE.json");
}

void begin_report(CLI::App& app, int argc, char** argv) {
  set_command_line(argc, argv);
  CLI::App* leaf = &app;
  for (;;) {
    const auto subs = leaf->get_subcommands();
    if (subs.empty()) break;
    leaf = subs.front();
  }
  CLI::Option* opt = leaf->get_option_no_throw("--report");
  if (opt == nullptr || opt->count() == 0) return;
  const fs::path path = opt->as<std::string>();
  std::string command;
  for (const CLI::App* a = leaf; a != nullptr && a->get_parent() != nullptr; a = a->get_parent())
    command = a->get_name() + (command.empty() ? "" : " " + command);
  if (lower(path.extension().string()) != ".json")
    throw OptionError(command + ": --report \"" + path.string() + "\": must end in .json");
  check_output_location(command, PathArg{"--report", path});

  auto s = std::make_unique<ReportState>();
  s->path = path;
  s->command = command;
  for (int i = 0; i < argc; ++i) s->argv.emplace_back(argv[i]);
  s->started_utc = utc_now();
  s->start = Clock::now();
  for (CLI::Option* o : leaf->get_options([](CLI::Option*) { return true; })) {
    const std::string name = o->get_name();
    if (name == "--help" || name == "--report" || name.empty()) continue;
    s->options[name] = option_value(o);
    if (o->count() > 0) s->options_given.push_back(name);
  }
  state() = std::move(s);
}

std::optional<fs::path> report_path() {
  if (!state()) return std::nullopt;
  return state()->path;
}

void note_report_input(const PathArg& input) {
  if (!state() || input.path.empty()) return;
  for (const auto& in : state()->inputs)
    if (in.path == input.path) return;
  state()->inputs.push_back(input);
}

void note_report_output(const PathArg& output) {
  if (!state() || output.path.empty()) return;
  for (const auto& out : state()->outputs)
    if (out.path == output.path) return;
  state()->outputs.push_back(output);
}

void note_report_summary(const std::string& title, const std::vector<SummaryRow>& rows) {
  if (!state()) return;
  state()->summaries.push_back(summary_json(title, rows));
}

void note_report_filter([[maybe_unused]] const std::string& label,
                        [[maybe_unused]] const FilterStats& s) {
#if defined(SCANCLEAN_HAVE_FILTER)
  if (!state()) return;
  ordered_json j;
  j["label"] = label;
  j["points_in"] = s.points_in;
  j["points_out"] = s.points_out;
  j["merged"] = s.merged;
  j["removed"] = s.removed();
  j["removed_by"] = {{"unsupported", s.unsupported}, {"off_surface", s.off_surface},
                     {"low_density", s.low_density}, {"low_likelihood", s.low_likelihood},
                     {"displaced", s.displaced},     {"small_components", s.small_components}};
  j["kernels"] = s.kernels;
  j["kernels_split"] = s.kernels_split;
  j["kernels_refitted"] = s.kernels_refitted;
  j["kernel_stride"] = s.kernel_stride;
  j["h_m"] = s.h;
  j["h_min_m"] = s.h_min;
  j["h_max_m"] = s.h_max;
  j["h0_m"] = s.h0;
  j["h_noise_m"] = s.h_noise;
  j["scale_crease_samples"] = s.scale_crease_samples;
  j["noise_sigma_m"] = s.noise_sigma;
  j["mean_spacing_m"] = s.mean_spacing;
  j["merge_eps_m"] = s.merge_eps;
  j["mean_iterations"] = s.mean_iterations;
  j["p95_iterations"] = s.p95_iterations;
  j["not_converged"] = s.not_converged;
  j["seconds"] = {{"scale", s.seconds_scale},           {"kernels", s.seconds_kernels},
                  {"projection", s.seconds_projection}, {"clustering", s.seconds_clustering},
                  {"outliers", s.seconds_outliers},     {"total", s.seconds_total}};
  j["peak_rss_bytes"] = s.peak_rss_bytes;
  j["threads"] = s.threads;
  state()->filter_runs.push_back(std::move(j));
#endif
}

bool end_report(int exit_code, const std::string& error) {
  if (!state()) return true;
  const std::unique_ptr<ReportState> s = std::move(state());
  const double run_seconds = seconds_since(s->start);
  try {
    const auto t_hash = Clock::now();
    ordered_json inputs = ordered_json::array(), outputs = ordered_json::array();
    for (const auto& in : s->inputs) inputs.push_back(describe_path(in));
    for (const auto& out : s->outputs) outputs.push_back(describe_path(out));
    const double hash_seconds = seconds_since(t_hash);
    ordered_json j;
    j["scanclean_report"] = 1;
    j["version"] = kScancleanVersion;
    j["command"] = s->command;
    j["command_line"] = s->argv;
    j["started_utc"] = s->started_utc;
    j["finished_utc"] = utc_now();
    j["exit_code"] = exit_code;
    j["error"] = error.empty() ? ordered_json() : ordered_json(error);
    j["options"] = s->options;
    j["options_given"] = s->options_given;
    j["inputs"] = std::move(inputs);
    j["outputs"] = std::move(outputs);
    j["summaries"] = s->summaries;
    j["filter"] = s->filter_runs;
    j["timings"] = {{"run_s", run_seconds}, {"hashing_s", hash_seconds}};
    const std::string text = j.dump(2) + "\n";
    write_file_atomically(s->path, [&](std::ostream& os) { os << text; });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scanclean: error: the report \"%s\" was not written: %s\n",
                 s->path.string().c_str(), e.what());
    return false;
  }
  return true;
}

std::string sha256_of_file(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(file.string() + ": cannot be opened to hash it");
  std::unique_ptr<EVP_MD_CTX, void (*)(EVP_MD_CTX*)> ctx(EVP_MD_CTX_new(), EVP_MD_CTX_free);
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1)
    throw IoError("SHA-256 is not available (OpenSSL)");
  std::vector<char> buf(1 << 20);
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const auto got = in.gcount();
    if (got > 0) EVP_DigestUpdate(ctx.get(), buf.data(), static_cast<std::size_t>(got));
  }
  if (in.bad()) throw IoError(file.string() + ": read failed while hashing it");
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_DigestFinal_ex(ctx.get(), md, &len);
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned int i = 0; i < len; ++i) {
    out += hex[md[i] >> 4];
    out += hex[md[i] & 15];
  }
  return out;
}

}  // namespace scanclean::app
