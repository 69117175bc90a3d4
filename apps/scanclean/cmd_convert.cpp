// scanclean convert: convert point clouds between PLY, PCD and XYZ; merge Stanford scan sessions.
#if defined(SCANCLEAN_HAVE_IO)

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/output_checks.h"
#include "scanclean/provenance.h"
#include "scanclean/run_report.h"
#include "scanclean/summary.h"

namespace scanclean::app {
namespace {

struct ConvertOptions {
  std::vector<std::string> files;
  bool ascii = false;
  std::string pcd_encoding = "binary_compressed";
  std::string conf;
  bool skip_missing = false;
};

int run_convert(const ConvertOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t want = o.conf.empty() ? 2 : 1;
  if (o.files.size() != want)
    throw OptionError(o.conf.empty() ? "convert: expected IN and OUT files"
                                     : "convert --conf FILE.conf: expected only the OUT file");
  const std::string out = o.files.back();
  const std::string input = o.conf.empty() ? o.files.front() : o.conf;
  const std::vector<PathArg> inputs{{o.conf.empty() ? "IN" : "--conf", input}};
  check_input_files("convert", inputs);
  check_output_files("convert", inputs, {{"OUT", out}});
  WriteOptions w;
  w.ply_encoding = o.ascii ? PlyEncoding::kAscii : PlyEncoding::kBinaryLittleEndian;
  w.pcd_encoding = o.pcd_encoding;
  w.provenance = provenance_text();
  validate(w);

  ReadReport r;
  const std::string in = o.conf.empty() ? o.files.front() : o.conf;
  const PointCloud cloud = o.conf.empty()
                               ? read_point_cloud(in, &r)
                               : read_and_merge_conf(in, &r, ConfOptions{o.skip_missing});
  for (const auto& warning : r.warnings)
    std::fprintf(stderr, "scanclean: warning: %s\n", warning.c_str());

  const std::string fmt = point_cloud_format(out);
  std::string lost;
  if (fmt == "xyz") {
    if (cloud.has_confidences()) lost += " confidences";
    if (cloud.has_intensities()) lost += " intensities";
    if (cloud.has_colors()) lost += " colours";
    for (const auto& a : cloud.attributes) lost += " " + a.name;
    if (!cloud.grid.empty()) lost += " grid";
  }
  write_point_cloud(out, cloud, w);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  Summary s("scanclean convert");
  s.add("input", in + " (" + r.format + (r.encoding.empty() ? "" : ", " + r.encoding) + ")");
  s.add("output", out + " (" + fmt +
                      (fmt == "ply"   ? (o.ascii ? ", ascii" : ", binary_little_endian")
                       : fmt == "pcd" ? ", " + o.pcd_encoding
                                      : ", text") +
                      ")");
  s.add_count("points", cloud.size());
  s.add_count("invalid dropped", r.dropped_invalid);
  if (!cloud.grid.empty())
    s.add("organized", std::to_string(cloud.grid.rows) + " x " + std::to_string(cloud.grid.cols));
  if (!lost.empty()) s.add("not written (xyz)", lost.substr(1));
  s.add_count("warnings", r.warnings.size());
  s.add("time", seconds, 2, "s");
  s.print();
  return 0;
}

const CommandRegistrar kRegistrar{{
    "convert",
    "Convert point clouds between PLY, PCD and XYZ; merge a Stanford .conf scan session",
    15,
    [](CLI::App& cmd) {
      auto o = std::make_shared<ConvertOptions>();
      cmd.add_option("files", o->files,
                     "IN OUT (or only OUT with --conf); formats by extension: .ply .pcd .xyz .txt")
          ->required();
      cmd.add_flag("--ascii", o->ascii, "Write ASCII PLY (default: binary little-endian)");
      cmd.add_option("--pcd-encoding", o->pcd_encoding, "PCD output encoding")
          ->check(CLI::IsMember({"ascii", "binary", "binary_compressed"}))
          ->default_val("binary_compressed");
      cmd.add_option("--conf", o->conf,
                     "Stanford .conf: read every bmesh scan, give its points normals from its "
                     "range grid (facing the scanner), bring it into the common frame "
                     "(R(q)^T p + t) and merge them into OUT");
      cmd.add_flag("--skip-missing", o->skip_missing,
                   "With --conf: merge the scans that exist and warn about missing files "
                   "(default: a missing scan is an error)");
      cmd.footer(
          "Everything the input carries is written when the output format can hold it: positions, "
          "normals, confidences, intensities, colours, named attributes (with their types) and the "
          "organized grid (PLY range_grid, organized PCD with NaN in empty cells). XYZ holds only "
          "positions and normals; the summary lists what was not written.\n"
          "Positions are stored as float unless that would move a point by more than 1e-6 of the "
          "bounding-box diagonal, then as double. Non-finite input points are dropped and "
          "counted.\n"
          "Units: PLY/PCD/XYZ carry no unit; values are copied unchanged (metres for the bundled "
          "data). Output is written atomically: on failure no partial file is left.\n"
          "Exit codes: 0 ok, 2 bad options, 3 bad input data, 4 file I/O failure.");
      add_report_option(cmd);
      return [o] { return run_convert(*o); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_IO
