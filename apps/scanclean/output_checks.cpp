#include "scanclean/output_checks.h"

#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstring>
#include <system_error>

#include "scanclean/core/errors.h"
#include "scanclean/run_report.h"

namespace scanclean::app {

namespace fs = std::filesystem;

namespace {

bool has_point_cloud_extension(const fs::path& p) {
  std::string e = p.extension().string();
  for (auto& ch : e) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return e == ".ply" || e == ".pcd" || e == ".xyz" || e == ".txt";
}

// The same file? Existing files are compared by identity (links included), others by their
// absolute, normalised path.
bool same_file(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  if (fs::exists(a, ec) && fs::exists(b, ec)) {
    const bool eq = fs::equivalent(a, b, ec);
    if (!ec) return eq;
  }
  const fs::path ca = fs::weakly_canonical(fs::absolute(a, ec), ec);
  const fs::path cb = fs::weakly_canonical(fs::absolute(b, ec), ec);
  return ca.lexically_normal() == cb.lexically_normal();
}

std::string named(const PathArg& a) {
  return a.option + " \"" + a.path.string() + "\"";
}

}  // namespace

void check_input_files(const std::string& command, const std::vector<PathArg>& inputs) {
  for (const auto& in : inputs) {
    if (in.path.empty()) continue;
    std::error_code ec;
    const auto st = fs::status(in.path, ec);
    if (!fs::exists(st)) throw IoError(command + ": " + named(in) + ": no such file");
    if (fs::is_directory(st))
      throw InputError(command + ": " + named(in) +
                       ": is a folder; expected a point-cloud file (.ply .pcd .xyz .txt)");
    note_report_input(in);
  }
}

void check_output_location(const std::string& command, const PathArg& out) {
  std::error_code ec;
  if (fs::is_directory(out.path, ec))
    throw OptionError(command + ": " + named(out) + ": is a folder; expected a file name");
  const fs::path folder = out.path.parent_path().empty() ? fs::path(".") : out.path.parent_path();
  if (!fs::is_directory(folder, ec))
    throw IoError(command + ": " + named(out) + ": the folder \"" + folder.string() +
                  "\" does not exist (create it first)");
  if (::access(folder.c_str(), W_OK | X_OK) != 0)
    throw IoError(command + ": " + named(out) + ": cannot write in the folder \"" +
                  folder.string() + "\": " + std::strerror(errno));
}

void check_output_files(const std::string& command, const std::vector<PathArg>& inputs,
                        const std::vector<PathArg>& outputs, bool point_cloud) {
  for (std::size_t i = 0; i < outputs.size(); ++i) {
    const PathArg& out = outputs[i];
    if (out.path.empty()) continue;
    if (point_cloud && !has_point_cloud_extension(out.path))
      throw OptionError(command + ": " + named(out) + ": must end in .ply, .pcd, .xyz or .txt");
    check_output_location(command, out);
    for (const auto& in : inputs)
      if (!in.path.empty() && same_file(out.path, in.path))
        throw OptionError(command + ": " + named(out) + " is the same file as the " + named(in) +
                          "; refusing to overwrite it (choose another output)");
    for (std::size_t j = 0; j < i; ++j)
      if (!outputs[j].path.empty() && same_file(out.path, outputs[j].path))
        throw OptionError(command + ": " + named(out) + " and " + named(outputs[j]) +
                          " are the same file; give them different names");
    note_report_output(out);
  }
  // The run's --report (run_report.h) must not overwrite an input or an output either.
  if (const auto report = report_path()) {
    const PathArg r{"--report", *report};
    for (const auto* list : {&inputs, &outputs})
      for (const auto& p : *list)
        if (!p.path.empty() && same_file(r.path, p.path))
          throw OptionError(command + ": " + named(r) + " is the same file as the " + named(p) +
                            "; give it another name");
  }
}

}  // namespace scanclean::app
