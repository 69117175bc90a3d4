// The capture-and-clean job shared by replay and capture (clean_job.h).

#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_FILTER) && \
    defined(SCANCLEAN_HAVE_PIPELINE) && defined(SCANCLEAN_HAVE_SOURCES)

#include "scanclean/clean_job.h"

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <cctype>
#include <chrono>
#include <cstdio>
#include <memory>
#include <vector>

#include "scanclean/command.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/progress.h"
#include "scanclean/filter_options_cli.h"
#include "scanclean/interrupt.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/output_checks.h"
#include "scanclean/preview.h"
#include "scanclean/provenance.h"
#include "scanclean/run_report.h"
#include "scanclean/summary.h"

namespace scanclean::app {

std::function<void(PipelineOptions&)> add_clean_options(CLI::App& cmd) {
  struct Values {
    int accumulate = 0;
    bool raw = false;
    int stencil = 2;
    int edge_margin = 2;
    double min_depth = 0, max_depth = 0;
    bool no_weights = false;
    bool no_fuse = false;
    double memory_budget_mib = 128;
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
  // Depth frames take the library's preset (the scale and displacement tests off; see
  // depth_frame_options() for why).
  const FilterCliValues depth_defaults = values_of(depth_frame_options());
  auto filter = add_filter_options(cmd, depth_defaults);
  cmd.add_option("--normal-stencil", v->stencil,
                 "Half-width s (pixels) of the sensor-normal stencil on the depth image")
      ->check(integer_in(1, 32))
      ->capture_default_str();
  cmd.add_option("--edge-margin", v->edge_margin,
                 "Drop pixels within this many pixels of a depth jump (flying pixels); 0 = off")
      ->check(integer_in(0, 32))
      ->capture_default_str();
  cmd.add_option("--min-depth", v->min_depth, "Drop points nearer than this (metres; 0 = off)")
      ->check(non_negative_number());
  cmd.add_option("--max-depth", v->max_depth, "Drop points farther than this (metres; 0 = off)")
      ->check(non_negative_number());
  cmd.add_flag("--no-weights", v->no_weights,
               "Do not weight points by the sensor noise model (Nguyen 2012 + PS1080 "
               "quantisation for PrimeSense-class sensors)");
  cmd.add_option("--memory-budget", v->memory_budget_mib,
                 "MiB of complete windows (their raw frames) that may wait for cleaning; beyond "
                 "it a live sensor's window is skipped for cleaning (counted and named in the "
                 "summary; --record keeps its frames), while a file source waits (files never "
                 "skip)")
      ->check(positive_number())
      ->capture_default_str();
  return [v, filter](PipelineOptions& o) {
    o.memory_budget_bytes = static_cast<std::size_t>(v->memory_budget_mib * 1048576.0);
    o.accumulate = static_cast<std::size_t>(v->accumulate);
    o.window.raw = v->raw;
    o.window.fuse = !v->no_fuse;
    o.window.filter = to_filter_options(*filter);
    o.window.points.normal_stencil = v->stencil;
    o.window.points.edge_margin_px = v->edge_margin;
    o.window.points.min_depth_m = v->min_depth;
    o.window.points.max_depth_m = v->max_depth;
    o.window.points.weights = !v->no_weights;
  };
}

std::function<void(const std::string&, SourceOptions&)> add_intrinsics_options(CLI::App& cmd) {
  struct Values {
    double fx = 0, fy = 0, cx = -1, cy = -1;
  };
  auto v = std::make_shared<Values>();
  auto* fx = cmd.add_option("--fx", v->fx, "Depth images: focal length x (pixels)")
                 ->check(positive_number());
  auto* fy = cmd.add_option("--fy", v->fy, "Depth images: focal length y (pixels)")
                 ->check(positive_number());
  auto* cx = cmd.add_option("--cx", v->cx, "Depth images: principal point x (pixels)")
                 ->check(non_negative_number());
  auto* cy = cmd.add_option("--cy", v->cy, "Depth images: principal point y (pixels)")
                 ->check(non_negative_number());
  const std::string name = cmd.get_name();
  return [v, fx, fy, cx, cy, name](const std::string& source, SourceOptions& so) {
    const std::size_t given = fx->count() + fy->count() + cx->count() + cy->count();
    if (given == 0) return;
    if (fx->count() == 0 || fy->count() == 0 || cx->count() == 0 || cy->count() == 0)
      throw OptionError(name + ": give all of --fx --fy --cx --cy (pixels) for depth images");
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path p(source);
    std::string ext = p.extension().string();
    for (auto& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    const bool own = source.find("://") != std::string::npos || ext == ".oni" ||
                     fs::exists(p / "session.json", ec) || fs::exists(p / "capture.json", ec) ||
                     fs::exists(p / "graycode_00.png", ec);
    if (own)
      throw OptionError(name + ": --fx --fy --cx --cy apply to depth images only; the source \"" +
                        source +
                        "\" (an .oni file, a device, a recording folder or a structured-light "
                        "capture) carries its own intrinsics");
    Intrinsics K;
    K.fx = v->fx;
    K.fy = v->fy;
    K.cx = v->cx;
    K.cy = v->cy;
    K.source = "calibration";
    so.K = K;
  };
}

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
    o.acquisition.max_frames = number(text);
    if (o.acquisition.max_frames == 0)
      throw OptionError("--frames \"" + text + "\": expected A:B or N > 0");
    return;
  }
  o.first_frame = number(text.substr(0, colon));
  o.acquisition.max_frames = number(text.substr(colon + 1));
}

void check_clean_outputs(const std::string& command, const PipelineOptions& options,
                         const std::filesystem::path& input, const std::filesystem::path& output,
                         const std::filesystem::path& outliers) {
  if (!outliers.empty() && options.window.raw)
    throw OptionError(command + ": --outliers needs the filter (it is off with --raw)");
  std::vector<PathArg> inputs;
  std::error_code ec;
  if (!input.empty() && std::filesystem::is_regular_file(input, ec))
    inputs.push_back({"the source", input});
  check_output_files(command, inputs, {{"-o", output}, {"--outliers", outliers}});
  std::error_code exists_ec;
  if (!input.empty() && std::filesystem::exists(input, exists_ec))
    note_report_input({"the source", input});  // a file or a folder (--report)
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

int run_clean_job(const std::string& command, RangeSource& source, PipelineOptions options,
                  const std::filesystem::path& output, const std::filesystem::path& outliers,
                  const std::string& preview, const LiveOutputs& live) {
  check_clean_outputs(command, options, {}, output, outliers);
  if (!live.latest.empty())
    check_output_files(command, {},
                       {{"-o", output}, {"--outliers", outliers}, {"--latest", live.latest}});
  if (!preview.empty() && options.window.raw)
    throw OptionError(command + ": --preview needs the filter (it is off with --raw)");
  check_preview_path(command, preview);
  options.window.keep_input = !preview.empty();
  std::string preview_text;  // the summary line, once the first window's preview is written
  validate(options);
  install_sigint_handler();
  options.acquisition.keep_going = [] { return !interrupted(); };
#ifdef __GLIBC__
  // Frames and clouds are large, short-lived blocks freed by other threads than the ones that
  // made them: with glibc's sliding mmap threshold they end up in per-thread heaps that keep
  // growing. A fixed threshold returns them to the system (a 30 s live run: 1.3 -> 0.9 GB peak).
  mallopt(M_MMAP_THRESHOLD, 256 * 1024);
  mallopt(M_ARENA_MAX, 2);
#endif

  std::fprintf(stderr, "scanclean %s: opening the source\n", command.c_str());
  source.open();
  const SourceInfo info = source.info();
  for (const auto& w : info.warnings)
    std::fprintf(stderr, "scanclean %s: warning: %s\n", command.c_str(), w.c_str());
  std::uint64_t expected = 0;
  if (info.frame_count) expected = *info.frame_count;
  if (options.acquisition.max_frames > 0 &&
      (expected == 0 || options.acquisition.max_frames < expected))
    expected = options.acquisition.max_frames;
  if (expected > options.first_frame) expected -= options.first_frame;
  // One bar over reading and cleaning: a frame counts once when read and once when its window
  // is cleaned (or skipped), so the bar moves while the filter runs.
  std::unique_ptr<Progress> bar;
  if (expected > 0)
    bar = std::make_unique<Progress>(command + ": frames read + cleaned", 2 * expected);
  options.on_frame = [&](std::uint64_t) {
    if (bar) bar->advance();
  };
  const bool status_lines = !bar && Progress::enabled();  // live: one line per cleaned window
  FilterStats phase_sum;                                  // filter phase times summed over windows

  std::vector<std::filesystem::path> written;
  std::vector<std::string> collapsed;  // windows not written: empty or one point
  std::size_t mostly_unsupported = 0;  // windows written with most points unsupported
  std::size_t windows_seen = 0;
  const bool single = options.accumulate == 0;
  std::vector<WindowOutput> pending;  // to know whether there is more than one window
  auto write_window = [&](const WindowOutput& w, bool numbered) {
    const std::filesystem::path p = numbered ? window_path(output, w.window) : output;
    const std::size_t in = options.window.raw ? w.cloud.size() : w.filter.points_in;
    if (!options.window.raw && ((in >= 1 && w.cloud.empty()) || (in >= 2 && w.cloud.size() == 1))) {
      collapsed.push_back(p.string() + ": " + std::to_string(w.cloud.size()) + " point(s) from " +
                          with_thousands(in) + " (h " + std::to_string(w.filter.h * 1e3) +
                          " mm, merge eps " + std::to_string(w.filter.merge_eps * 1e3) + " mm)");
      return;
    }
    if (!options.window.raw && w.filter.unsupported * 2 > w.filter.points_in) {
      // Written, but most of the window had no kernel support: said once, counted at the end.
      if (mostly_unsupported++ == 0) {
        std::fprintf(stderr, "scanclean %s: window %zu (%s):\n", command.c_str(), w.window,
                     p.string().c_str());
        warn_if_mostly_unsupported(w.filter.unsupported, w.filter.points_in, w.filter.h);
      }
    }
    AtomicCommitGroup both;  // the cloud and its outliers, or neither
    WriteOptions wo;         // provenance: command line, h, noise sigma
    wo.provenance =
        options.window.raw ? provenance_text() : provenance_text(w.filter.h, w.filter.noise_sigma);
    write_point_cloud(p, w.cloud, wo);
    if (!outliers.empty())
      write_point_cloud(numbered ? window_path(outliers, w.window) : outliers, w.outliers, wo);
    both.commit();
    note_report_output({"-o", p});
    if (!options.window.raw) note_report_filter(p.string(), w.filter);
    if (!preview.empty() && preview_text.empty()) {
      PreviewOptions po;
      po.view = PreviewView::kCamera;
      po.title = command_line();
      preview_text =
          preview_summary_text(preview, write_preview(preview, w.input, w.cloud, w.outliers, po));
    }
    written.push_back(p);
  };
  const auto t_start = std::chrono::steady_clock::now();
  const PipelineStats st = run_pipeline(
      source, options,
      [&](WindowOutput&& w) {
        if (bar) bar->advance(w.frames);
        phase_sum.seconds_scale += w.filter.seconds_scale;
        phase_sum.seconds_kernels += w.filter.seconds_kernels;
        phase_sum.seconds_projection += w.filter.seconds_projection;
        phase_sum.seconds_clustering += w.filter.seconds_clustering;
        phase_sum.seconds_outliers += w.filter.seconds_outliers;
        phase_sum.seconds_total += w.filter.seconds_total;
        if (!live.latest.empty() && !w.cloud.empty()) write_point_cloud(live.latest, w.cloud);
        if (status_lines)
          std::fprintf(
              stderr,
              "scanclean %s: window %zu cleaned (frames %llu..%llu, %zu points) at %.1f s\n",
              command.c_str(), w.window, static_cast<unsigned long long>(w.first_frame),
              static_cast<unsigned long long>(w.last_frame), w.cloud.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count());
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
  if (bar) {
    for (const auto& k : st.skipped) bar->advance(k.last_frame - k.first_frame + 1);
    bar->finish();
  }
  source.close();

  Summary sum("scanclean " + command);
  sum.add("source",
          info.uri + " (" + info.kind + (info.name.empty() ? "" : ", " + info.name) + ")");
  if (!info.warnings.empty()) sum.add_count("source warnings", info.warnings.size());
  sum.add("stopped", to_string(st.stop) + (st.message.empty() ? "" : ": " + st.message));
  sum.add_count("frames delivered", st.frames_read);
  if (!live.record.empty())
    sum.add("frames recorded",
            with_thousands(st.frames_recorded) + " (in " + live.record.string() + ")");
  sum.add_count("frames used", st.frames_used);
  if (!options.window.raw) sum.add_count("frames cleaned", st.frames_cleaned);
  {
    // Every skipped window, as runs of consecutive windows: "5-9 (frames 150..299), 11 (...)".
    std::string names;
    for (std::size_t i = 0; i < st.skipped.size();) {
      std::size_t j = i;
      while (j + 1 < st.skipped.size() && st.skipped[j + 1].window == st.skipped[j].window + 1) ++j;
      names += (i ? ", " : ": ") + std::to_string(st.skipped[i].window) +
               (j > i ? "-" + std::to_string(st.skipped[j].window) : std::string()) + " (frames " +
               std::to_string(st.skipped[i].first_frame) + ".." +
               std::to_string(st.skipped[j].last_frame) + ")";
      i = j + 1;
    }
    sum.add("windows skipped", with_thousands(st.skipped.size()) +
                                   (st.skipped.empty() ? std::string()
                                                       : names + "; cleaning fell behind, replay "
                                                                 "the recording to clean them"));
  }
  sum.add("dropped frames (index gaps)",
          with_thousands(st.dropped_frames) + " in " + with_thousands(st.gap_events) + " gaps" +
              (st.trailing_dropped_frames > 0
                   ? " (" + with_thousands(st.trailing_dropped_frames) + " at the end)"
                   : std::string()));
  sum.add_count("timeouts", st.timeouts);
  if (st.disconnects > 0)
    sum.add("disconnects", with_thousands(st.disconnects) + " (" + with_thousands(st.reconnects) +
                               " reconnected, " + with_thousands(st.reconnect_lost_frames) +
                               " frames lost while reconnecting)");
  if (st.frames_cleaned > 0)  // over the frames of the cleaned (or raw) windows
    sum.add("points per frame", with_thousands(st.min_points_per_frame) + " min, " +
                                    with_thousands(st.points_in / st.frames_cleaned) + " mean, " +
                                    with_thousands(st.max_points_per_frame) + " max");
  sum.add_count("flying pixels dropped", st.edge_dropped);
  sum.add_count("points in", st.points_in);
  if (st.points_fused > 0)
    sum.add("fused per pixel", with_thousands(st.points_fused) + " points (" +
                                   with_thousands(st.fusion_rejected) +
                                   " samples off their pixel's median depth dropped)");
  sum.add_count("points out", st.points_out);
  if (!options.window.raw) sum.add_count("outliers removed", st.outliers);
  sum.add("filter", options.window.raw ? std::string("off (--raw)") : std::string("robust filter"));
  sum.add_count("windows", st.windows);
  sum.add("time", "read " + seconds_text(st.seconds_read) + ", points " +
                      seconds_text(st.seconds_points) + ", filter " +
                      seconds_text(st.seconds_filter));
  if (!options.window.raw && st.windows > 0)
    sum.add("filter phases", "scale " + seconds_text(phase_sum.seconds_scale) + ", kernels " +
                                 seconds_text(phase_sum.seconds_kernels) + ", projection " +
                                 seconds_text(phase_sum.seconds_projection) + ", clustering " +
                                 seconds_text(phase_sum.seconds_clustering) + ", outliers " +
                                 seconds_text(phase_sum.seconds_outliers));
  if (st.windows > 0)
    sum.add("latency (frame -> window)",
            "p50 " + seconds_text(st.latency_p50_s) + ", p95 " + seconds_text(st.latency_p95_s));
  sum.add("total", st.seconds_total, 2, "s");
  if (written.empty()) {
    sum.add("output", collapsed.empty() ? "none (no frames)" : "none");
  } else if (written.size() == 1) {
    sum.add("output", written.front().string());
  } else {
    sum.add("output", std::to_string(written.size()) + " files: " + written.front().string() +
                          " .. " + written.back().string());
  }
  if (!collapsed.empty()) sum.add_count("windows not written (collapsed)", collapsed.size());
  if (mostly_unsupported > 0)
    sum.add_count("windows mostly unsupported (written)", mostly_unsupported);
  if (!preview_text.empty()) sum.add("preview", preview_text);
  sum.print();
  if (mostly_unsupported > 1)
    std::fprintf(stderr,
                 "scanclean %s: warning: %zu windows in all left more than half of their points "
                 "unsupported (the first is named above)\n",
                 command.c_str(), mostly_unsupported);
  if (st.stop == StopReason::kInterrupted) return static_cast<int>(ExitCode::kInterrupted);
  if (st.stop == StopReason::kError) {
    std::fprintf(stderr, "scanclean %s: error: the source failed: %s\n", command.c_str(),
                 st.message.c_str());
    return static_cast<int>(ExitCode::kBadInput);
  }
  if (st.reconnect_budget_exhausted) {
    std::fprintf(stderr,
                 "scanclean %s: error: the source kept disconnecting: %s (what was captured "
                 "before is written)\n",
                 command.c_str(), st.message.c_str());
    return static_cast<int>(ExitCode::kUnavailable);
  }
  if (st.frames_used == 0) {
    std::fprintf(stderr, "scanclean %s: error: no frame was read (%s)\n", command.c_str(),
                 to_string(st.stop));
    return static_cast<int>(ExitCode::kBadInput);
  }
  if (!collapsed.empty()) {
    for (const auto& c : collapsed)
      std::fprintf(stderr,
                   "scanclean %s: error: the result is empty or collapsed, not written: %s; "
                   "check --h, --k and --merge-eps\n",
                   command.c_str(), c.c_str());
    return static_cast<int>(ExitCode::kEmptyResult);
  }
  return 0;
}

}  // namespace scanclean::app

#endif
