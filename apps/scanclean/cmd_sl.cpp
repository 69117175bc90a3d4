// scanclean sl: structured light (Gray code). `sl patterns` writes the projector images and
// capture.json; `sl decode` decodes a capture folder, triangulates it with the camera-projector
// calibration, optionally filters the points and writes a point cloud; `sl calibrate` computes
// the camera-projector calibration from chessboard captures.

#if defined(SCANCLEAN_HAVE_SL)

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/progress.h"
#include "scanclean/drivers/sl_board.h"
#include "scanclean/drivers/sl_calibrate.h"
#include "scanclean/drivers/sl_plane_fit.h"
#include "scanclean/drivers/structured_light_source.h"
#include "scanclean/mesh_handoff.h"
#include "scanclean/output_checks.h"
#include "scanclean/preview.h"
#include "scanclean/provenance.h"
#include "scanclean/run_report.h"
#include "scanclean/summary.h"
#if defined(SCANCLEAN_HAVE_IO)
#include "scanclean/io/point_cloud_io.h"
#endif
#if defined(SCANCLEAN_HAVE_FILTER)
#include "scanclean/filter/robust_filter.h"
#include "scanclean/filter_options_cli.h"
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
  // sub-stripe decoding (decode, calibrate)
  bool integer = false;
  int sub_stripe_level = 0;
  // chessboard (decode --fit-plane, calibrate)
  std::string board = "9x7";
  double square_m = 0.075;
  double window_m = 0.30;
  std::string residual_map;
  double residual_range_m = 0.005;
  // calibrate
  std::vector<std::string> captures;
  std::string kamino_xml;
  std::string compare;
  int corner_window = 20;
  bool estimate_k3 = false;
  bool zero_tangential = false;
  std::shared_ptr<MeshHandoff> mesh;                                       // --mesh FILE
  std::shared_ptr<std::string> preview = std::make_shared<std::string>();  // --preview
};

//! The extension of an output must be one of `exts`; its folder must exist and be writable,
//! and it must not be one of `inputs` (the shared checks of every command, output_checks.h).
void check_output(const std::string& command, const std::string& option, const std::string& file,
                  const std::vector<std::string>& exts, const std::vector<PathArg>& inputs = {}) {
  const std::filesystem::path p(file);
  std::string ext = p.extension().string();
  for (auto& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  bool ok = false;
  std::string list;
  for (const auto& e : exts) {
    ok = ok || ext == e;
    list += (list.empty() ? "" : " ") + e;
  }
  if (!ok) throw OptionError(option + ": '" + file + "' must end in one of: " + list);
  check_output_files(command, inputs, {{option, p}}, false);
}

SlChessboard chessboard_of(const SlCommandOptions& c) {
  SlChessboard b;
  parse_chessboard_size(c.board, b);
  b.square_m = c.square_m;
  validate(b);
  return b;
}

std::string mm(double metres, int precision = 3) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f mm", precision, metres * 1e3);
  return buf;
}

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

void plane_rms(Summary& sum, const PointCloud& pc, double band, const char* key) {
  if (pc.size() < 3) return;
  PlaneFitOptions po;
  po.inlier_threshold = band;
  const PlaneFit f = fit_plane_robust(pc.positions, po);
  sum.add(key, std::to_string(f.rms * 1e3).substr(0, 6) + " mm RMS over " +
                   std::to_string(100.0 * f.inliers.size() / pc.size()).substr(0, 5) +
                   " % of the points (band " + std::to_string(band * 1e3).substr(0, 5) + " mm)");
}

//! Summary lines "<prefix>board" and "<prefix>window" (RMS, p95, points) of one cloud.
SlBoardMeasurement board_report(Summary& sum, const std::vector<Eigen::Vector3d>& points,
                                const SlBoardRegion& region, const SlBoardMeasureOptions& bo,
                                const std::string& where, const std::string& prefix) {
  const SlBoardMeasurement m = measure_sl_board(points, region, bo, where);
  auto line = [](const SlPlaneStats& s) {
    return mm(s.rms_m) + " RMS, " + mm(s.p95_m) + " p95 over " + with_thousands(s.points) +
           " points (" + std::to_string(100.0 * s.inliers).substr(0, 5) + " % in the band)";
  };
  sum.add(prefix + "board plane", line(m.board));
  char win[64];
  std::snprintf(win, sizeof win, "%s%.0fx%.0f cm window", prefix.c_str(), bo.window_m * 100,
                bo.window_m * 100);
  sum.add(win, line(m.window));
  return m;
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
  o.sub_stripe = !c.integer;
  o.sub_stripe_level = c.sub_stripe_level;
  if (!c.projector.empty())
    std::tie(o.projector_width, o.projector_height) = parse_size(c.projector);
  validate(o);
  if (!(c.plane_band > 0)) throw OptionError("--plane-band: expected > 0 metres");
  if (c.filter_h < 0) throw OptionError("--filter-h: expected > 0 metres (or 0 = automatic)");
  SlBoardMeasureOptions bo;
  bo.board = chessboard_of(c);
  bo.window_m = c.window_m;
  bo.band_m = c.plane_band;
  validate(bo);
  if (!(c.residual_range_m > 0)) throw OptionError("--residual-range: expected > 0 metres");
  if (!c.residual_map.empty()) {
    if (!c.fit_plane) throw OptionError("--residual-map needs --fit-plane");
    check_output("sl decode", "--residual-map", c.residual_map + "_raw.png", {".png"});
  }
  check_output("sl decode", "-o", c.output, {".ply", ".pcd", ".xyz"});
  check_mesh_output(*c.mesh, "sl decode");
  if (!c.preview->empty() && !c.filter) throw OptionError("sl decode: --preview needs --filter");
  check_preview_path("sl decode", *c.preview);
  note_report_input({"capture", c.capture});
  if (!c.calib.empty()) note_report_input({"--calib", c.calib});
  note_report_output({"-o", c.output});
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
  std::string provenance = provenance_text();  // with the filter's h when it runs

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
  {
    const double unit = c.unit_m > 0 ? c.unit_m : r.calibration.unit_m;
    char u[64];
    std::snprintf(u, sizeof u, "%g m", unit);
    sum.add("calibration", r.calibration.file.string() + " (unit " + u +
                               (r.calibration.unit_assumed && c.unit_m == 0 ? ", assumed" : "") +
                               ")");
  }
  const double pixels = static_cast<double>(r.decoded.status.size());
  sum.add("lit pixels", 100.0 * r.decoded.lit / pixels, 1, "%");
  sum.add("valid pixels", 100.0 * r.decoded.valid / pixels, 1, "%");
  sum.add("decode",
          std::string(to_string(r.decoded.decoder)) +
              (o.sub_stripe ? ", sub-stripe (level " + std::to_string(o.sub_stripe_level) + ")"
                            : ", integer") +
              ", " + std::to_string(r.decoded.seconds * 1e3).substr(0, 6) + " ms (load " +
              std::to_string(r.load_seconds).substr(0, 5) + " s)");
  if (o.sub_stripe)
    sum.add("sub-stripe pixels",
            100.0 * r.decoded.sub_stripe_pixels /
                std::max<double>(1.0, static_cast<double>(r.decoded.valid)),
            1, "% of the valid (both axes between two edges)");
  sum.add_count("triangulated", r.triangulation.points);
  sum.add("epipolar check",
          with_thousands(r.triangulation.rejected_reprojection) + " rejected (> " +
              std::to_string(c.max_reprojection_px).substr(0, 5) + " px), mean " +
              std::to_string(r.triangulation.mean_reprojection_px).substr(0, 5) + " px");
  sum.add_count("points", cloud.size());
  sum.add("points from", how);

  // --fit-plane: the chessboard's plane residual (board_report), else the whole scene's.
  std::optional<SlBoardRegion> region;
  std::optional<SlBoardMeasurement> raw_board;
  if (c.fit_plane) {
    const SlBoardCorners corners = find_sl_board_corners(r.capture, r.decoded, bo.board);
    if (corners.found) {
      region.emplace(corners, r.calibration, bo, c.capture);
      const SlSquareSize sq = measure_sl_squares(corners, r.calibration, bo.board);
      sum.add("board", std::to_string(bo.board.cols) + "x" + std::to_string(bo.board.rows) +
                           " inner corners, " + std::to_string(corners.projector_found()) +
                           " decoded; square " + mm(sq.mean_m) + " mean, " + mm(sq.std_m) +
                           " sd over " + std::to_string(sq.count) + " (" +
                           mm(bo.board.square_m, 1) + " nominal)");
      raw_board =
          board_report(sum, cloud.positions, *region, bo, c.capture, c.filter ? "raw " : "");
      if (!c.residual_map.empty()) {
        write_sl_residual_map(c.residual_map + "_raw.png", cloud.positions, *raw_board, *region,
                              r.calibration, c.residual_range_m);
        sum.add("residual map", c.residual_map + "_raw.png");
      }
    } else {
      sum.add("board", "chessboard " + c.board + " not found; plane over the whole scene");
      plane_rms(sum, cloud, c.plane_band, c.filter ? "plane residual before" : "plane residual");
    }
  }
  if (c.filter) {
#if defined(SCANCLEAN_HAVE_FILTER)
    FilterCliValues fv;  // the shared mapping (filter_options_cli.h)
    fv.h = c.filter_h;
    fv.threads = c.threads;
    FilterOptions fo = to_filter_options(fv);
    FilterProgress progress(fo);
    validate(fo);
    FilterResult fr = robust_filter(cloud, fo);
    progress.finish();
    if (!c.preview->empty()) {
      PreviewOptions po;
      po.view = PreviewView::kCamera;
      po.title = command_line();
      sum.add("preview", preview_summary_text(*c.preview, write_preview(*c.preview, cloud, fr.cloud,
                                                                        fr.outliers, po)));
    }
    note_report_filter(c.output, fr.stats);
    provenance = provenance_text(fr.stats.h, fr.stats.noise_sigma);
    sum.add("filter", with_thousands(fr.stats.points_out) + " points out, h " +
                          std::to_string(fr.stats.h * 1e3).substr(0, 6) + " mm, " +
                          std::to_string(fr.stats.seconds_total).substr(0, 5) + " s");
    cloud = std::move(fr.cloud);
    if (region) {
      const SlBoardMeasurement m =
          board_report(sum, cloud.positions, *region, bo, c.capture, "filtered ");
      if (!c.residual_map.empty()) {
        write_sl_residual_map(c.residual_map + "_filtered.png", cloud.positions, m, *region,
                              r.calibration, c.residual_range_m);
        sum.add("residual map", c.residual_map + "_filtered.png");
      }
    } else if (c.fit_plane) {
      plane_rms(sum, cloud, c.plane_band, "plane residual after");
    }
#else
    throw UnavailableError("sl decode --filter: this build has no filter module");
#endif
  }
  WriteOptions w;
  if (c.ascii) {
    w.ply_encoding = PlyEncoding::kAscii;
    w.pcd_encoding = "ascii";
  }
  w.provenance = provenance;
  write_point_cloud(c.output, cloud, w);
  sum.add("output file", c.output + " (metres, camera frame)");
  run_mesh_handoff(*c.mesh, cloud, 0.0, sum);
  sum.print();
  return 0;
#endif
}

//! Relative difference in percent, as text.
std::string pct(double ours, double theirs) {
  char b[48];
  std::snprintf(b, sizeof b, "%+.2f %%", 100.0 * (ours - theirs) / theirs);
  return b;
}

void compare_calibrations(Summary& sum, const SlCalibration& ours, const SlCalibration& ref,
                          int ref_step) {
  char b[256];
  const Intrinsics &a = ours.camera, &r = ref.camera;
  std::snprintf(b, sizeof b, "fx %s, fy %s, cx %+.1f px, cy %+.1f px, k1 %+.3f, k2 %+.3f",
                pct(a.fx, r.fx).c_str(), pct(a.fy, r.fy).c_str(), a.cx - r.cx, a.cy - r.cy,
                a.dist[0] - r.dist[0], a.dist[1] - r.dist[1]);
  sum.add("vs reference: camera", b);
  // The reference's projector pixels are ref_step decoded pixels.
  const Intrinsics &p = ours.projector, &q = ref.projector;
  const double s = 1.0 / ref_step;
  std::snprintf(b, sizeof b,
                "fx %s, fy %s, cx %+.1f px, cy %+.1f px (reference / %d: Gray-code step %d)",
                pct(p.fx, q.fx * s).c_str(), pct(p.fy, q.fy * s).c_str(), p.cx - q.cx * s,
                p.cy - q.cy * s, ref_step, ref_step);
  sum.add("vs reference: projector", b);
  const Eigen::Vector3d t_ours = ours.T * ours.unit_m, t_ref = ref.T * ref.unit_m;
  const Eigen::AngleAxisd dr(ours.R * ref.R.transpose());
  std::snprintf(
      b, sizeof b, "%.1f mm vs %.1f mm (%s), direction %.2f deg apart, rotation %.3f deg apart",
      t_ours.norm() * 1e3, t_ref.norm() * 1e3, pct(t_ours.norm(), t_ref.norm()).c_str(),
      std::acos(std::clamp(t_ours.normalized().dot(t_ref.normalized()), -1.0, 1.0)) * 180 / M_PI,
      dr.angle() * 180 / M_PI);
  sum.add("vs reference: baseline", b);
}

int run_calibrate(const SlCommandOptions& c) {
  SlCalibrateOptions co;
  co.board = chessboard_of(c);
  co.corners.window_radius_px = c.corner_window;
  co.estimate_k3 = c.estimate_k3;
  co.zero_tangential = c.zero_tangential;
  validate(co);
  const std::vector<PathArg> references = {{"--compare", c.compare}};
  check_output("sl calibrate", "-o", c.output, {".yml", ".yaml"}, references);
  if (!c.kamino_xml.empty()) {
    check_output("sl calibrate", "--kamino-xml", c.kamino_xml, {".xml"}, references);
    check_output_files("sl calibrate", references,
                       {{"-o", c.output}, {"--kamino-xml", c.kamino_xml}}, false);
  }
  for (const auto& a : c.captures) note_report_input({"captures", a});
  std::vector<std::filesystem::path> folders;
  for (const auto& a : c.captures) {
    const auto found = find_structured_light_captures(a);
    if (found.empty())
      throw InputError(a, "", "not a structured-light capture (capture.json or graycode_00.png)");
    folders.insert(folders.end(), found.begin(), found.end());
  }
  if (static_cast<int>(folders.size()) < co.min_views)
    throw OptionError("sl calibrate: " + std::to_string(folders.size()) + " capture(s) given, " +
                      std::to_string(co.min_views) + " board poses needed");
  int pw = 0, ph = 0;
  if (!c.projector.empty()) std::tie(pw, ph) = parse_size(c.projector);
  std::optional<SlCalibration> reference;
  if (!c.compare.empty()) reference = read_sl_calibration(c.compare);
  std::vector<SlCapture> captures;
  std::vector<SlDecoded> decoded;
  double decode_s = 0;
  {
    Progress bar("sl calibrate: load + decode", folders.size());
    for (const auto& f : folders) {
      const SlCaptureInfo info = describe_sl_capture(f, pw, ph);
      captures.push_back(SlCapture::load(info));
      SlDecodeOptions d;
      d.white_threshold = c.white_threshold >= 0 ? c.white_threshold : info.white_threshold;
      d.black_threshold = c.black_threshold >= 0 ? c.black_threshold : info.black_threshold;
      d.sub_stripe = !c.integer;
      d.sub_stripe_level = c.sub_stripe_level;
      d.threads = c.threads;
      decoded.push_back(decode_graycode(captures.back(), d));
      decode_s += decoded.back().seconds;
      bar.advance(1);
    }
  }
  const SlCalibrateResult res = calibrate_sl(captures, decoded, co);
  write_sl_calibration(c.output, res.calibration);
  if (!c.kamino_xml.empty()) write_sl_calibration_kamino(c.kamino_xml, res.calibration);

  Summary sum("scanclean sl calibrate");
  sum.add("captures", std::to_string(folders.size()) + " (" +
                          std::to_string(captures.front().width()) + "x" +
                          std::to_string(captures.front().height()) + " camera, " +
                          std::to_string(res.calibration.projector.width) + "x" +
                          std::to_string(res.calibration.projector.height) + " projector)");
  sum.add("board", c.board + " inner corners, squares " + mm(co.board.square_m, 1));
  sum.add("decode", std::string(c.integer ? "integer" : "sub-stripe") + ", " +
                        std::to_string(decode_s * 1e3 / folders.size()).substr(0, 6) +
                        " ms per capture");
  for (const auto& v : res.views) {
    char b[200];
    if (v.used)
      std::snprintf(b, sizeof b, "%d corners, reprojection camera %.3f px, projector %.3f px",
                    v.corners, v.camera_rms_px, v.projector_rms_px);
    else
      std::snprintf(b, sizeof b, "not used: %s", v.reason.c_str());
    sum.add("view " + std::filesystem::path(v.name).filename().string(), b);
  }
  char b[256];
  std::snprintf(b, sizeof b, "camera %.3f px, projector %.3f px, stereo %.3f px", res.camera_rms_px,
                res.projector_rms_px, res.stereo_rms_px);
  sum.add("reprojection RMS", b);
  const auto& K = res.calibration.camera;
  const auto& P = res.calibration.projector;
  std::snprintf(b, sizeof b,
                "fx %.1f fy %.1f cx %.1f cy %.1f; k1 %.4f k2 %.4f p1 %.5f p2 %.5f k3 %.4f", K.fx,
                K.fy, K.cx, K.cy, K.dist[0], K.dist[1], K.dist[2], K.dist[3], K.dist[4]);
  sum.add("camera", b);
  std::snprintf(b, sizeof b,
                "fx %.1f fy %.1f cx %.1f cy %.1f; k1 %.4f k2 %.4f p1 %.5f p2 %.5f k3 %.4f", P.fx,
                P.fy, P.cx, P.cy, P.dist[0], P.dist[1], P.dist[2], P.dist[3], P.dist[4]);
  sum.add("projector", b);
  const Eigen::Vector3d t = res.calibration.T * 1e3;
  std::snprintf(b, sizeof b, "T (%.1f, %.1f, %.1f) mm, |T| %.1f mm", t.x(), t.y(), t.z(), t.norm());
  sum.add("camera -> projector", b);
  if (reference) {
    int step = reference->graycode_step;
    if (reference->layout == "kamino410") {
      SlCalibration ref = *reference;
      ref.projector.width = captures.front().info().graycode.projector_width;
      ref.projector.height = captures.front().info().graycode.projector_height;
      step = estimate_graycode_step(decoded.front(), ref);
    }
    compare_calibrations(sum, res.calibration, *reference, step);
  }
  sum.add("written", c.output + (c.kamino_xml.empty() ? "" : ", " + c.kamino_xml));
  sum.print();
  return 0;
}

void add_sub_stripe_options(CLI::App* app, SlCommandOptions& c) {
  app->add_flag("--integer", c.integer,
                "Integer Gray-code decode (whole projector pixels) instead of the sub-stripe "
                "decode (edges of the Gray-code stripes located where pattern and inverse "
                "cross, projector coordinate interpolated between them)");
  app->add_option("--sub-stripe-level", c.sub_stripe_level,
                  "Finest Gray-code bit whose stripe edges are used (0 = every edge; raise it "
                  "when the camera does not resolve the finest stripes)")
      ->default_val(0);
}

void add_board_options(CLI::App* app, SlCommandOptions& c) {
  app->add_option("--board", c.board, "Chessboard inner corners COLSxROWS")->default_val("9x7");
  app->add_option("--square", c.square_m, "Chessboard square side, metres")->default_val(0.075);
}

CLI::App* add_calibrate_command(CLI::App& cmd, SlCommandOptions& c) {
  auto* cal = cmd.add_subcommand(
      "calibrate",
      "Calibrate camera, projector and their pose from three or more captures of a chessboard "
      "under the Gray-code sequence (corners in the camera by OpenCV, in the projector by local "
      "homographies of the decoded pixels, Moreno & Taubin 2012); writes calib.yml (metres, "
      "Gray-code step 1)");
  cal->add_option("captures", c.captures,
                  "Capture folders (or folders of captures), one board pose each")
      ->required();
  cal->add_option("-o,--output", c.output, "Output calib.yml")->required();
  add_report_option(*cal);
  cal->add_option("--kamino-xml", c.kamino_xml,
                  "Also write kamino410/procam-calibration's calibration_result.xml layout "
                  "(translation in millimetres)");
  cal->add_option("--compare", c.compare,
                  "Reference calibration to report the differences to (e.g. the rig's "
                  "calibration_result.xml)");
  cal->add_option("--corner-window", c.corner_window,
                  "Half side of the local homography window around each corner, camera pixels")
      ->default_val(20);
  cal->add_flag("--k3", c.estimate_k3,
                "Also estimate the 6th-order radial distortion k3 (needs many, varied poses; "
                "default k3 = 0)");
  cal->add_flag("--zero-tangential", c.zero_tangential,
                "Fix the tangential distortion p1 = p2 = 0");
  cal->add_option("--projector", c.projector,
                  "Projector size WxH (kamino410 captures without ../graycode_pattern/)");
  cal->add_option("--black-threshold", c.black_threshold,
                  "Shadow mask threshold (gray levels; default: the capture's, else 40)");
  cal->add_option("--white-threshold", c.white_threshold,
                  "Bit threshold (gray levels; default: the capture's, else 5)");
  cal->add_option("--threads", c.threads, "Worker threads, 0 = all cores")->default_val(0);
  add_sub_stripe_options(cal, c);
  add_board_options(cal, c);
  return cal;
}

const CommandRegistrar kRegistrar{{
    "sl",
    "Structured light (Gray code): write projector patterns, calibrate the rig, decode captures "
    "to point clouds",
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
                      "Bit threshold stored in capture.json (gray levels, default 5)")
          ->check(integer_in(0, 255));
      pat->add_option("--black-threshold", c->black_threshold,
                      "Shadow threshold stored in capture.json (gray levels, default 40)")
          ->check(integer_in(0, 255));

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
                      "capture.json's, else 40)")
          ->check(integer_in(0, 255));
      dec->add_option("--white-threshold", c->white_threshold,
                      "Every bit needs |I - I_inverse| >= this (gray levels; default: "
                      "capture.json's, else 5)")
          ->check(integer_in(0, 255));
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
                    "Find the chessboard (--board, --square) and report its plane residual "
                    "(whole board and central window: RMS, 95th percentile; raw and, with "
                    "--filter, filtered) and the square size measured from the triangulated "
                    "corners; without a board, the residual to a plane over the whole scene");
      dec->add_option("--plane-band", c->plane_band,
                      "Inlier band half-width of the plane fit, metres")
          ->default_val(0.01);
      dec->add_flag("--ascii", c->ascii, "Write ASCII PLY/PCD instead of binary");
      add_sub_stripe_options(dec, *c);
      add_board_options(dec, *c);
      dec->add_option("--window", c->window_m,
                      "--fit-plane: side of the central board window, metres (along the board)")
          ->default_val(0.30);
      dec->add_option("--residual-map", c->residual_map,
                      "--fit-plane: write PREFIX_raw.png (and PREFIX_filtered.png with --filter), "
                      "the board's residual to its plane per camera pixel");
      dec->add_option("--residual-range", c->residual_range_m,
                      "Colour range of the residual maps, +- metres")
          ->default_val(0.005);
      c->mesh = add_mesh_option(*dec);
      add_report_option(*dec);
      c->preview = add_preview_option(*dec);
      dec->add_option("--threads", c->threads, "Worker threads, 0 = all cores (same result)")
          ->default_val(0);
      auto* cal = add_calibrate_command(cmd, *c);
      return [c, pat, cal] {
        if (pat->parsed()) return run_patterns(*c);
        if (cal->parsed()) return run_calibrate(*c);
        return run_decode(*c);
      };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_SL
