// scanclean sl: structured light (Gray code). `sl patterns` writes the projector images and
// capture.json; `sl decode` decodes a capture folder, triangulates it with the camera-projector
// calibration, optionally filters the points and writes a point cloud.

#if defined(SCANCLEAN_HAVE_SL)

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/progress.h"
#include "scanclean/drivers/sl_plane_fit.h"
#include "scanclean/drivers/structured_light_source.h"
#include "scanclean/mesh_handoff.h"
#include "scanclean/summary.h"
#if defined(SCANCLEAN_HAVE_IO)
#include "scanclean/io/point_cloud_io.h"
#endif
#if defined(SCANCLEAN_HAVE_FILTER)
#include "scanclean/filter/robust_filter.h"
#endif
#if defined(SCANCLEAN_HAVE_PIPELINE)
#include "scanclean/pipeline/frame_to_points.h"
#endif

namespace scanclean::app {
namespace {

struct SlCommandOptions {
  // patterns
  std::string projector;
  std::string pattern_dir;
  // decode
  std::string capture;
  std::string output;
  std::string calib;
  std::string decoder = "fast";
  int white_threshold = -1;
  int black_threshold = -1;
  int graycode_step = 0;
  double unit_m = 0;
  double max_reprojection_px = 10.0;
  bool filter = false;
  double filter_h = 0;
  bool fit_plane = false;
  double plane_band = 0.01;
  bool ascii = false;
  int threads = 0;
  std::shared_ptr<MeshHandoff> mesh;  // --mesh FILE
};

std::pair<int, int> parse_size(const std::string& s) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X') ||
      w < 2 || h < 2 || w > 65535 || h > 65535)
    throw OptionError("--projector: expected WxH with 2..65535 pixels each (e.g. 1024x768), got '" +
                      s + "'");
  return {w, h};
}

int run_patterns(const SlCommandOptions& c) {
  const auto [w, h] = parse_size(c.projector);
  const int white = c.white_threshold >= 0 ? c.white_threshold : 5;
  const int black = c.black_threshold >= 0 ? c.black_threshold : 40;
  const int n = write_graycode_patterns(c.pattern_dir, w, h, white, black);
  const GrayCodeLayout l = graycode_layout(w, h);
  Summary sum("scanclean sl patterns");
  sum.add("projector", std::to_string(w) + "x" + std::to_string(h));
  sum.add("Gray-code bits", std::to_string(l.column_bits) + " column + " +
                                std::to_string(l.row_bits) + " row (each with its inverse)");
  sum.add("images", std::to_string(n) + " (" + std::to_string(l.pattern_count()) +
                        " patterns, white " + std::to_string(l.pattern_count()) + ", black " +
                        std::to_string(l.pattern_count() + 1) + ")");
  sum.add("written", (std::filesystem::path(c.pattern_dir) / "patterns").string() +
                         "/000.png.., capture.json");
  sum.add("thresholds", "white " + std::to_string(white) + ", black " + std::to_string(black));
  sum.add("next",
          "project patterns/NNN.png in order, save camera image k as <capture>/img/NNN.png; "
          "put capture.json and calib.yml beside img/");
  sum.print();
  return 0;
}

PointCloud frame_cloud(const RangeFrame& frame, std::string* how) {
#if defined(SCANCLEAN_HAVE_PIPELINE)
  SourceInfo info;
  info.kind = "structured-light";
  info.noise_model = "structured-light";
  info.K = frame.K;
  *how = "frame_to_points (normals, edge pixels dropped)";
  return frame_to_points(frame, info);
#else
  *how = "valid pixels (no normals)";
  return sl_frame_to_cloud(frame);
#endif
}

int run_decode(const SlCommandOptions& c) {
#if !defined(SCANCLEAN_HAVE_IO)
  (void)c;
  throw UnavailableError("sl decode: this build has no io module (cannot write point clouds)");
#else
  SlOptions o;
  o.white_threshold = c.white_threshold;
  o.black_threshold = c.black_threshold;
  o.calibration = c.calib;
  o.decoder = parse_sl_decoder(c.decoder);
  o.graycode_step = c.graycode_step;
  o.threads = c.threads;
  o.triangulation.max_reprojection_px = c.max_reprojection_px;
  o.triangulation.calibration_unit_m = c.unit_m;
  if (!c.projector.empty())
    std::tie(o.projector_width, o.projector_height) = parse_size(c.projector);
  validate(o);
  if (!(c.plane_band > 0)) throw OptionError("--plane-band: expected > 0 metres");
  if (c.filter_h < 0) throw OptionError("--filter-h: expected > 0 metres (or 0 = automatic)");
  check_mesh_output(*c.mesh, "sl decode");
  if (!is_structured_light_capture(c.capture)) {
    const auto found = find_structured_light_captures(c.capture);
    throw InputError(c.capture, "",
                     found.empty()
                         ? "not a structured-light capture (capture.json or graycode_00.png)"
                         : "a folder of " + std::to_string(found.size()) +
                               " captures; decode them one at a time (e.g. " +
                               found.front().string() + ")");
  }
  const SlResult r = process_sl_capture(c.capture, o);
  std::string how;
  PointCloud cloud = frame_cloud(r.frame, &how);

  Summary sum("scanclean sl decode");
  sum.add("capture", c.capture + " (" + r.info.layout + " layout)");
  sum.add("camera", std::to_string(r.decoded.status.width) + "x" +
                        std::to_string(r.decoded.status.height) + ", " +
                        std::to_string(r.info.images.size()) + " images");
  sum.add("projector",
          std::to_string(r.info.graycode.projector_width) + "x" +
              std::to_string(r.info.graycode.projector_height) + " Gray code, step " +
              std::to_string(r.calibration.graycode_step) +
              (r.graycode_step_estimated
                   ? " (estimated, median reprojection " +
                         std::to_string(r.step_median_reprojection_px).substr(0, 5) + " px)"
                   : ""));
  sum.add("calibration", r.calibration.file.string() + " (unit " +
                             std::to_string(r.calibration.unit_m * 1000).substr(0, 6) + " mm" +
                             (r.calibration.unit_assumed && c.unit_m == 0 ? ", assumed" : "") +
                             ")");
  const double pixels = static_cast<double>(r.decoded.status.size());
  sum.add("lit pixels", 100.0 * r.decoded.lit / pixels, 1, "%");
  sum.add("valid pixels", 100.0 * r.decoded.valid / pixels, 1, "%");
  sum.add("decode", std::string(to_string(r.decoded.decoder)) + ", " +
                        std::to_string(r.decoded.seconds * 1e3).substr(0, 6) + " ms (load " +
                        std::to_string(r.load_seconds).substr(0, 5) + " s)");
  sum.add_count("triangulated", r.triangulation.points);
  sum.add("epipolar check",
          with_thousands(r.triangulation.rejected_reprojection) + " rejected (> " +
              std::to_string(c.max_reprojection_px).substr(0, 5) + " px), mean " +
              std::to_string(r.triangulation.mean_reprojection_px).substr(0, 5) + " px");
  sum.add_count("points", cloud.size());
  sum.add("points from", how);

  auto plane_rms = [&](const PointCloud& pc, const char* key) {
    if (pc.size() < 3) return;
    PlaneFitOptions po;
    po.inlier_threshold = c.plane_band;
    const PlaneFit f = fit_plane_robust(pc.positions, po);
    sum.add(key, std::to_string(f.rms * 1e3).substr(0, 6) + " mm RMS over " +
                     std::to_string(100.0 * f.inliers.size() / pc.size()).substr(0, 5) +
                     " % of the points (band " + std::to_string(c.plane_band * 1e3).substr(0, 5) +
                     " mm)");
  };
  if (c.fit_plane) plane_rms(cloud, c.filter ? "plane residual before" : "plane residual");

  if (c.filter) {
#if defined(SCANCLEAN_HAVE_FILTER)
    FilterOptions fo;
    if (c.filter_h > 0) {
      fo.scale = ScaleMode::kFixed;
      fo.h = c.filter_h;
    }
    fo.threads = c.threads;
    std::unique_ptr<Progress> bar;
    std::string phase;
    std::uint64_t done = 0;
    fo.progress = [&](const std::string& p, double fraction) {
      if (p != phase) {
        bar.reset();
        bar = std::make_unique<Progress>("filter: " + p, 1000);
        phase = p;
        done = 0;
      }
      const auto target = static_cast<std::uint64_t>(fraction * 1000.0);
      if (target > done) {
        bar->advance(target - done);
        done = target;
      }
    };
    validate(fo);
    FilterResult fr = robust_filter(cloud, fo);
    bar.reset();
    sum.add("filter", with_thousands(fr.stats.points_out) + " points out, h " +
                          std::to_string(fr.stats.h * 1e3).substr(0, 6) + " mm, " +
                          std::to_string(fr.stats.seconds_total).substr(0, 5) + " s");
    cloud = std::move(fr.cloud);
    if (c.fit_plane) plane_rms(cloud, "plane residual after");
#else
    throw UnavailableError("sl decode --filter: this build has no filter module");
#endif
  }
  WriteOptions w;
  if (c.ascii) {
    w.ply_encoding = PlyEncoding::kAscii;
    w.pcd_encoding = "ascii";
  }
  write_point_cloud(c.output, cloud, w);
  sum.add("output file", c.output + " (metres, camera frame)");
  run_mesh_handoff(*c.mesh, cloud, 0.0, sum);
  sum.print();
  return 0;
#endif
}

const CommandRegistrar kRegistrar{{
    "sl",
    "Structured light (Gray code): write projector patterns, decode captures to point clouds",
    40,
    [](CLI::App& cmd) {
      auto c = std::make_shared<SlCommandOptions>();
      cmd.require_subcommand(1);
      auto* pat = cmd.add_subcommand(
          "patterns",
          "Write the Gray-code projector images (OpenCV GrayCodePattern order: column bits MSB "
          "first, then row bits, each followed by its inverse; then white, black) as 8-bit PNG "
          "into DIR/patterns/ and DIR/capture.json describing them");
      pat->add_option("--projector", c->projector, "Projector size WxH in pixels, e.g. 1024x768")
          ->required();
      pat->add_option("-o,--output", c->pattern_dir, "Output folder")->required();
      pat->add_option("--white-threshold", c->white_threshold,
                      "Bit threshold stored in capture.json (gray levels, default 5)");
      pat->add_option("--black-threshold", c->black_threshold,
                      "Shadow threshold stored in capture.json (gray levels, default 40)");

      auto* dec = cmd.add_subcommand(
          "decode",
          "Decode a capture folder (capture.json + img/NNN.png, or kamino410's graycode_NN.png), "
          "triangulate with the calibration (calib.yml or calibration_result.xml, here or in the "
          "parent folder) and write the points (metres, camera frame)");
      dec->add_option("capture", c->capture, "Capture folder")->required();
      dec->add_option("-o,--output", c->output, "Output point cloud (.ply .pcd .xyz)")->required();
      dec->add_flag("--filter", c->filter,
                    "Run the robust filter on the points (decode confidences as weights)");
      dec->add_option("--filter-h", c->filter_h,
                      "Fixed filter kernel h in metres (default automatic; for coarse projector "
                      "quantization use about twice the depth step)");
      dec->add_option("--black-threshold", c->black_threshold,
                      "Shadow mask: white - black must exceed this (gray levels; default: "
                      "capture.json's, else 40)");
      dec->add_option("--white-threshold", c->white_threshold,
                      "Every bit needs |I - I_inverse| >= this (gray levels; default: "
                      "capture.json's, else 5)");
      dec->add_option("--calib", c->calib, "Calibration file (overrides the one found beside)");
      dec->add_option("--decoder", c->decoder,
                      "'fast' (vectorised, default) or 'opencv' (GrayCodePattern::getProjPixel "
                      "per pixel; same result, slower)")
          ->check(CLI::IsMember({"fast", "opencv"}));
      dec->add_option("--projector", c->projector,
                      "Projector size WxH (needed for kamino410 captures without "
                      "../graycode_pattern/)");
      dec->add_option("--graycode-step", c->graycode_step,
                      "Projector pixel = step x decoded pixel (kamino410's graycode_step); "
                      "default: the calibration's, estimated for kamino410 calibrations");
      dec->add_option("--unit-m", c->unit_m,
                      "Metres per calibration length unit (default: calib.yml's 'units'; "
                      "kamino410 files: 0.001, i.e. millimetres assumed)");
      dec->add_option("--max-reprojection", c->max_reprojection_px,
                      "Reject pixels whose column and row disagree by more than this many "
                      "projector pixels (epipolar check)")
          ->default_val(10.0);
      dec->add_flag("--fit-plane", c->fit_plane,
                    "Report the RMS residual to a robust plane fit (flat targets)");
      dec->add_option("--plane-band", c->plane_band,
                      "Inlier band half-width of the plane fit, metres")
          ->default_val(0.01);
      dec->add_flag("--ascii", c->ascii, "Write ASCII PLY/PCD instead of binary");
      c->mesh = add_mesh_option(*dec);
      dec->add_option("--threads", c->threads, "Worker threads, 0 = all cores (same result)")
          ->default_val(0);
      return [c, pat] { return pat->parsed() ? run_patterns(*c) : run_decode(*c); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_SL
