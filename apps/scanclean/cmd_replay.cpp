// scanclean replay: any finite source (recording folder, depth images, .oni, structured-light
// capture, vsensor://) -> points -> robust filter -> PLY/PCD. Also holds the capture-and-clean
// job shared with cmd_capture.cpp (run_clean_job, add_clean_options, the SIGINT flag).

#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_FILTER) && \
    defined(SCANCLEAN_HAVE_PIPELINE) && defined(SCANCLEAN_HAVE_SOURCES)

#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/progress.h"
#include "scanclean/drivers/make_range_source.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/mesh_handoff.h"
#include "scanclean/pipeline/pipeline.h"
#include "scanclean/summary.h"

namespace scanclean::app {

namespace {
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_sigint(int) {
  g_interrupted = 1;
}
}  // namespace

// Shared with cmd_capture.cpp and cmd_record.cpp (declared there).
void install_sigint_handler() {
  g_interrupted = 0;
  std::signal(SIGINT, on_sigint);
}
bool interrupted() {
  return g_interrupted != 0;
}

// Adds the frame-to-points and filter options to `cmd`; the returned function copies the
// parsed values into PipelineOptions.
std::function<void(PipelineOptions&)> add_clean_options(CLI::App& cmd) {
  struct Values {
    int accumulate = 0;
    bool raw = false;
    double h = 0;
    int k = 0;
    int k_h = FilterOptions{}.k_h;
    double noise_factor = FilterOptions{}.noise_factor;
    // Off for depth frames: on the PS1080's quantised depth the scale test reads the depth steps
    // as structure and lowers h (the bundled recording's wall: 46 -> 39 mm), which leaves the
    // walls locally rougher (bench/README.md, "Defaults").
    double scale_gamma = 0;
    double likelihood_ratio = FilterOptions{}.likelihood_ratio;
    // Off for depth frames as well: on the bundled recording it drops 1,288 points (0.55 %) a
    // median 5.6 mm from the cleaned surface at a median depth of 3.7 m, where the sensor's
    // depth noise is several times that: surface points, not outliers.
    double displacement_sigma = 0;
    double outlier_sigma = FilterOptions{}.outlier_sigma;
    double merge_eps = -1;
    double tau = FilterOptions{}.tau;
    int threads = 0;
    int passes = 1;
    int stencil = 2;
    int edge_margin = 2;
    double min_depth = 0, max_depth = 0;
    bool no_weights = false;
    bool no_sensor_normals = false;
    bool no_fuse = false;
  };
  auto v = std::make_shared<Values>();
  cmd.add_option("--accumulate", v->accumulate,
                 "Frames per output cloud: each window of N frames is filtered into one cloud "
                 "(OUT_0000.ply, OUT_0001.ply, ... when there are several); 0 = all frames into "
                 "one (default)")
      ->check(non_negative_number());
  cmd.add_flag("--no-fuse", v->no_fuse,
               "Filter every sample of a window instead of fusing the window's frames per pixel "
               "first (fusion assumes a static view, as accumulation does; it averages each "
               "pixel's consistent samples and weights the point by their count)");
  cmd.add_flag("--raw", v->raw,
               "Skip the robust filter: write the back-projected points (with sensor normals and "
               "confidences)");
  cmd.add_option("--h", v->h, "Fixed filter kernel size h (metres); default automatic")
      ->check(positive_number());
  cmd.add_option("--k", v->k, "Adaptive kernels: h_i = distance to the k-th neighbour")
      ->check(CLI::Range(2, 1000));
  cmd.add_option("--k-h", v->k_h, "Neighbour rank of the automatic h")->capture_default_str();
  cmd.add_option("--noise-factor", v->noise_factor,
                 "Automatic h: at least this many times the estimated noise sigma")
      ->capture_default_str();
  cmd.add_option("--scale-gamma", v->scale_gamma,
                 "Automatic h, last step: the scale test's interval width in standard errors; "
                 "0 = off (default here: on quantised depth frames it lowers h and leaves "
                 "walls rougher); 3 = the filter command's default")
      ->check(CLI::Range(0.0, 20.0))
      ->capture_default_str();
  cmd.add_option("--merge-eps", v->merge_eps,
                 "Merge converged points closer than this (metres); 0 = keep all; default 0.25 x "
                 "mean spacing");
  cmd.add_option("--tau", v->tau, "Drop points with density < tau x median density (0 = off)")
      ->capture_default_str();
  cmd.add_option("--outlier-sigma", v->outlier_sigma,
                 "Drop points farther than this many standard deviations from every kernel "
                 "refitted without them (0 = off)")
      ->capture_default_str();
  cmd.add_option("--likelihood-ratio", v->likelihood_ratio,
                 "Drop points with likelihood < this x the lower quartile of the likelihoods "
                 "within h (0 = off)")
      ->capture_default_str();
  cmd.add_option("--displacement-sigma", v->displacement_sigma,
                 "Drop points whose move along the normal differs from the median move within "
                 "h by more than this many robust standard deviations; 0 = off (default here: "
                 "on depth frames it takes surface points within the sensor noise); 4 = the "
                 "filter command's default")
      ->capture_default_str();
  cmd.add_option("--passes", v->passes, "Filter passes (1 or 2)")->default_val(1);
  cmd.add_option("--threads", v->threads,
                 "Filter threads, 0 = all cores (the result is identical for any value)")
      ->default_val(0);
  cmd.add_option("--normal-stencil", v->stencil,
                 "Half-width s (pixels) of the sensor-normal stencil on the depth image")
      ->default_val(2);
  cmd.add_option("--edge-margin", v->edge_margin,
                 "Drop pixels within this many pixels of a depth jump (flying pixels); 0 = off")
      ->default_val(2);
  cmd.add_option("--min-depth", v->min_depth, "Drop points nearer than this (metres; 0 = off)");
  cmd.add_option("--max-depth", v->max_depth, "Drop points farther than this (metres; 0 = off)");
  cmd.add_flag("--no-weights", v->no_weights,
               "Do not weight points by the sensor noise model (Nguyen 2012 + PS1080 "
               "quantisation for PrimeSense-class sensors)");
  cmd.add_flag("--no-sensor-normals", v->no_sensor_normals,
               "Let the filter estimate normals by PCA instead of using the sensor normals");
  return [v](PipelineOptions& o) {
    o.accumulate = static_cast<std::size_t>(v->accumulate);
    o.raw = v->raw;
    o.fuse = !v->no_fuse;
    if (v->h > 0) {
      o.filter.scale = ScaleMode::kFixed;
      o.filter.h = v->h;
    } else if (v->k > 0) {
      o.filter.scale = ScaleMode::kAdaptive;
      o.filter.k_adaptive = v->k;
    }
    o.filter.k_h = v->k_h;
    o.filter.noise_factor = v->noise_factor;
    o.filter.scale_gamma = v->scale_gamma;
    o.filter.likelihood_ratio = v->likelihood_ratio;
    o.filter.displacement_sigma = v->displacement_sigma;
    o.filter.outlier_sigma = v->outlier_sigma;
    o.filter.merge_eps = v->merge_eps;
    o.filter.tau = v->tau;
    o.filter.passes = v->passes;
    o.filter.threads = v->threads;
    o.filter.use_sensor_normals = !v->no_sensor_normals;
    o.points.normal_stencil = v->stencil;
    o.points.edge_margin_px = v->edge_margin;
    o.points.min_depth_m = v->min_depth;
    o.points.max_depth_m = v->max_depth;
    o.points.weights = !v->no_weights;
  };
}

namespace {

std::filesystem::path window_path(const std::filesystem::path& out, std::size_t window) {
  char suffix[32];
  std::snprintf(suffix, sizeof suffix, "_%04zu", window);
  return out.parent_path() / (out.stem().string() + suffix + out.extension().string());
}

std::string seconds_text(double s) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f s", s);
  return b;
}

}  // namespace

// Runs the capture-and-clean job on `source` (not yet opened) and writes the outputs. Returns
// the exit code: 0, 130 after SIGINT (what was captured is written), 3 on a read error.
int run_clean_job(const std::string& command, RangeSource& source, PipelineOptions options,
                  const std::filesystem::path& output, const std::filesystem::path& outliers) {
  auto check_format = [&](const std::string& what, const std::filesystem::path& path) {
    if (point_cloud_format(path).empty())
      throw OptionError(command + ": " + what + " \"" + path.string() +
                        "\" must end in .ply, .pcd, .xyz or .txt");
  };
  check_format("output", output);
  if (!outliers.empty()) check_format("--outliers", outliers);
  if (!outliers.empty() && options.raw)
    throw OptionError(command + ": --outliers needs the filter (it is off with --raw)");
  validate(options);
  install_sigint_handler();
  options.keep_going = [] { return !interrupted(); };

  std::fprintf(stderr, "scanclean %s: opening the source\n", command.c_str());
  source.open();
  const SourceInfo info = source.info();
  std::uint64_t expected = 0;
  if (info.frame_count) expected = *info.frame_count;
  if (options.last_frame > 0 && (expected == 0 || options.last_frame < expected))
    expected = options.last_frame;
  if (expected > options.first_frame) expected -= options.first_frame;
  std::unique_ptr<Progress> bar;
  if (expected > 0) bar = std::make_unique<Progress>(command + ": frames", expected);
  options.on_frame = [&](std::uint64_t) {
    if (bar) bar->advance();
  };
  std::vector<std::filesystem::path> written;
  std::size_t windows_seen = 0;
  const bool single = options.accumulate == 0;
  std::vector<WindowOutput> pending;  // to know whether there is more than one window
  auto write_window = [&](const WindowOutput& w, bool numbered) {
    const std::filesystem::path p = numbered ? window_path(output, w.window) : output;
    write_point_cloud(p, w.cloud);
    written.push_back(p);
    if (!outliers.empty())
      write_point_cloud(numbered ? window_path(outliers, w.window) : outliers, w.outliers);
  };
  const PipelineStats st = run_pipeline(
      source, options,
      [&](WindowOutput&& w) {
        ++windows_seen;
        if (single) {
          write_window(w, false);
        } else if (windows_seen == 1) {
          pending.push_back(std::move(w));  // numbered only if a second window follows
        } else {
          for (auto& p : pending) write_window(p, true);
          pending.clear();
          write_window(w, true);
        }
      },
      true);
  for (auto& p : pending) write_window(p, false);
  if (bar) bar->finish();
  source.close();

  Summary sum("scanclean " + command);
  sum.add("source",
          info.uri + " (" + info.kind + (info.name.empty() ? "" : ", " + info.name) + ")");
  sum.add("stopped", to_string(st.stop) + (st.message.empty() ? "" : ": " + st.message));
  sum.add_count("frames read", st.frames_read);
  sum.add_count("frames used", st.frames_used);
  sum.add("dropped frames (index gaps)",
          with_thousands(st.dropped_frames) + " in " + with_thousands(st.gap_events) + " gaps");
  sum.add_count("timeouts", st.timeouts);
  if (st.disconnects > 0)
    sum.add("disconnects", with_thousands(st.disconnects) + " (" + with_thousands(st.reconnects) +
                               " reconnected)");
  if (st.frames_used > 0)
    sum.add("points per frame", with_thousands(st.min_points_per_frame) + " min, " +
                                    with_thousands(st.points_in / st.frames_used) + " mean, " +
                                    with_thousands(st.max_points_per_frame) + " max");
  sum.add_count("flying pixels dropped", st.edge_dropped);
  sum.add_count("points in", st.points_in);
  if (st.points_fused > 0)
    sum.add("fused per pixel", with_thousands(st.points_fused) + " points (" +
                                   with_thousands(st.fusion_rejected) +
                                   " samples off their pixel's median depth dropped)");
  sum.add_count("points out", st.points_out);
  if (!options.raw) sum.add_count("outliers removed", st.outliers);
  sum.add("filter", options.raw ? std::string("off (--raw)") : std::string("robust filter"));
  sum.add_count("windows", st.windows);
  sum.add("time", "read " + seconds_text(st.seconds_read) + ", points " +
                      seconds_text(st.seconds_points) + ", filter " +
                      seconds_text(st.seconds_filter));
  sum.add("total", st.seconds_total, 2, "s");
  if (written.empty()) {
    sum.add("output", "none (no frames)");
  } else if (written.size() == 1) {
    sum.add("output", written.front().string());
  } else {
    sum.add("output", std::to_string(written.size()) + " files: " + written.front().string() +
                          " .. " + written.back().string());
  }
  sum.print();
  if (st.stop == StopReason::kInterrupted) return static_cast<int>(ExitCode::kInterrupted);
  if (st.stop == StopReason::kError) {
    std::fprintf(stderr, "scanclean %s: error: the source failed: %s\n", command.c_str(),
                 st.message.c_str());
    return static_cast<int>(ExitCode::kBadInput);
  }
  if (st.frames_used == 0) {
    std::fprintf(stderr, "scanclean %s: error: no frame was read (%s)\n", command.c_str(),
                 to_string(st.stop));
    return static_cast<int>(ExitCode::kBadInput);
  }
  return 0;
}

// Parses "A:B", "A:" or ":B" (delivery positions, B exclusive) into the options.
void parse_frame_range(const std::string& text, PipelineOptions& o) {
  const auto colon = text.find(':');
  auto number = [&](const std::string& s) -> std::uint64_t {
    if (s.empty()) return 0;
    std::size_t used = 0;
    unsigned long long v = 0;
    try {
      v = std::stoull(s, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != s.size() || s[0] == '-')
      throw OptionError("--frames \"" + text +
                        "\": expected A:B with frame numbers (from 0, B "
                        "exclusive), e.g. 0:12, 5: or :30");
    return v;
  };
  if (colon == std::string::npos) {
    o.first_frame = 0;
    o.last_frame = number(text);
    if (o.last_frame == 0) throw OptionError("--frames \"" + text + "\": expected A:B or N > 0");
    return;
  }
  o.first_frame = number(text.substr(0, colon));
  o.last_frame = number(text.substr(colon + 1));
}

namespace {

struct ReplayCommandOptions {
  std::string source;
  std::string output;
  std::string outliers;
  std::string frames;
  std::string depth_format = "auto";
  double fx = 0, fy = 0, cx = -1, cy = -1;
  bool paced = false;
  std::shared_ptr<MeshHandoff> mesh;  // --mesh FILE
};

int run_replay(const ReplayCommandOptions& c, const std::function<void(PipelineOptions&)>& apply) {
  PipelineOptions o;
  apply(o);
  if (!c.frames.empty()) parse_frame_range(c.frames, o);
  SourceOptions so;
  so.depth_format = c.depth_format;
  so.recorded_pacing = c.paced;
  if (c.fx > 0 || c.fy > 0) {
    if (!(c.fx > 0 && c.fy > 0 && c.cx >= 0 && c.cy >= 0))
      throw OptionError("replay: give all of --fx --fy --cx --cy (pixels) for depth images");
    Intrinsics K;
    K.fx = c.fx;
    K.fy = c.fy;
    K.cx = c.cx;
    K.cy = c.cy;
    K.source = "calibration";
    so.K = K;
  }
  check_mesh_output(*c.mesh, "replay");
  auto source = make_range_source(c.source, so);
  const int rc = run_clean_job("replay", *source, o, c.output, c.outliers);
  return mesh_written_output(*c.mesh, c.output, "replay", rc);
}

const CommandRegistrar kRegistrar{{
    "replay",
    "Clean a recorded source: frames -> points (sensor normals, noise weights) -> robust filter",
    40,
    [](CLI::App& cmd) {
      auto c = std::make_shared<ReplayCommandOptions>();
      cmd.add_option("source", c->source, "The source: " + accepted_sources_help())->required();
      cmd.add_option("-o,--output", c->output,
                     "Output point cloud (.ply .pcd .xyz, metres, camera frame)")
          ->required();
      cmd.add_option("--outliers", c->outliers,
                     "Also write the points the filter removed (flags: 1 unsupported, 2 "
                     "outlier), numbered like the output when there are several windows");
      cmd.add_option("--frames", c->frames,
                     "Frame range A:B (delivery order from 0, B exclusive; A: = to the end, N = "
                     "the first N)");
      cmd.add_option("--depth-format", c->depth_format,
                     "Depth images: tum (1/5000 m), mm, nyu (raw disparity) or auto")
          ->check(CLI::IsMember({"auto", "tum", "mm", "nyu"}))
          ->default_val("auto");
      cmd.add_option("--fx", c->fx, "Depth images: focal length x (pixels)");
      cmd.add_option("--fy", c->fy, "Depth images: focal length y (pixels)");
      cmd.add_option("--cx", c->cx, "Depth images: principal point x (pixels)");
      cmd.add_option("--cy", c->cy, "Depth images: principal point y (pixels)");
      cmd.add_flag("--paced", c->paced,
                   "Recording folders: reproduce the recorded frame timing (default: as fast as "
                   "possible)");
      auto apply = add_clean_options(cmd);
      c->mesh = add_mesh_option(cmd);
      return [c, apply] { return run_replay(*c, apply); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif
