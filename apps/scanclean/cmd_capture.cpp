// scanclean capture: live capture-and-clean from any source URI (a sensor through openni2://,
// vsensor://, or a file), optionally recording the raw frames to a recording folder.

#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_FILTER) &&        \
    defined(SCANCLEAN_HAVE_PIPELINE) && defined(SCANCLEAN_HAVE_SOURCES) && \
    defined(SCANCLEAN_HAVE_REPLAY)

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "scanclean/clean_job.h"
#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/drivers/make_range_source.h"
#include "scanclean/pipeline/pipeline.h"
#include "scanclean/preview.h"
#include "scanclean/replay/frame_recorder.h"
#include "scanclean/run_report.h"

namespace scanclean::app {

namespace {

struct CaptureCommandOptions {
  std::string source = "openni2://";
  std::string output;
  std::string outliers;
  std::string record;
  std::string latest;
  std::uint64_t frames = 0;
  double seconds = 0;
  int reconnect = 0;
  bool depth_100um = false;
  std::shared_ptr<std::string> preview;  // --preview FILE.png
};

int run_capture(const CaptureCommandOptions& c, const std::function<void(PipelineOptions&)>& apply,
                const std::function<void(const std::string&, SourceOptions&)>& intrinsics) {
  PipelineOptions o;
  apply(o);
  o.acquisition.max_frames = c.frames;
  o.acquisition.max_seconds = c.seconds;
  o.acquisition.reconnect_attempts = c.reconnect;
  SourceOptions so;
  so.depth_100um = c.depth_100um;
  intrinsics(c.source, so);
  check_clean_outputs("capture", o, c.source, c.output, c.outliers);
  std::unique_ptr<RangeSource> source = make_range_source(c.source, so);
  // The acquisition stage records every frame it reads (PipelineOptions::record).
  std::unique_ptr<FrameRecorder> recorder;
  if (!c.record.empty()) {
    std::error_code ec;
    const std::filesystem::path rec(c.record);
    if (std::filesystem::exists(rec / "session.json", ec) ||
        std::filesystem::exists(rec / "frames.csv", ec))
      throw IoError(c.record +
                    ": already holds a recording (session.json or frames.csv); refusing to "
                    "overwrite it (give --record a new folder)");
    recorder = std::make_unique<FrameRecorder>(c.record);
    o.record = [&recorder](const SourceInfo& info, const RangeFrame& f) {
      recorder->write(info, f);
    };
  }
  LiveOutputs live;
  live.latest = c.latest;
  live.record = c.record;
  const int rc = run_clean_job("capture", *source, o, c.output, c.outliers, *c.preview, live);
  source.reset();
  if (recorder) recorder->finish();
  if (!c.record.empty())
    std::fprintf(stderr, "scanclean capture: raw frames recorded in %s\n", c.record.c_str());
  return rc;
}

const CommandRegistrar kRegistrar{{
    "capture",
    "Live capture-and-clean: frames from a sensor (or any source) -> robust filter -> point cloud",
    42,
    [](CLI::App& cmd) {
      auto c = std::make_shared<CaptureCommandOptions>();
      cmd.add_option("--source", c->source,
                     "Source URI: openni2:// (first sensor, default), openni2://<device uri>, "
                     "vsensor://<folder>, or any path `scanclean replay` accepts")
          ->default_val("openni2://");
      cmd.add_option("-o,--output", c->output, "Output point cloud (.ply .pcd .xyz, metres)")
          ->required();
      cmd.add_option("--outliers", c->outliers,
                     "Also write the points the filter removed (flags: 1 unsupported, 2 "
                     "outlier), numbered like the output when there are several windows");
      cmd.add_option("--record", c->record,
                     "Also record the raw frames to this recording folder (format v1, crash-safe; "
                     "replay it later with scanclean replay)");
      cmd.add_option("--latest", c->latest,
                     "Keep the latest cleaned window at this path (.ply .pcd .xyz), rewritten "
                     "atomically after every window, so that a viewer can reload it");
      auto* f =
          cmd.add_option("--frames", c->frames, "Stop after N frames")->check(positive_number());
      auto* s =
          cmd.add_option("--seconds", c->seconds, "Stop after S seconds")->check(positive_number());
      (void)f;
      (void)s;
      cmd.add_option("--reconnect", c->reconnect,
                     "After a disconnect, reopen the device; at most this many attempts over the "
                     "whole capture (a device that keeps disconnecting ends with exit 5; default "
                     "0: stop cleanly at the first disconnect, keeping what was captured)")
          ->check(integer_in(0, 1000000))
          ->default_val(0);
      cmd.add_flag("--depth-100um", c->depth_100um, "Live sensors: 0.1 mm depth units");
      cmd.footer(
          "Stops at the end of a finite source, after --frames/--seconds, on a disconnect, or on "
          "Ctrl-C (exit 130; what was captured is filtered and written). Reading never waits "
          "for the filter: windows queue for cleaning up to --memory-budget; beyond it a live "
          "sensor's window is skipped for cleaning (named in the summary) but still recorded "
          "with --record. With no sensor: "
          "\"no depth sensor found; run scanclean devices\", exit 5.\n"
          "A device that keeps disconnecting until the --reconnect budget is used up: exit 5.\n"
          "Exit codes: 0 ok, 1 internal error, 2 bad command line or option, 3 bad input data,\n"
          "4 file I/O failure, 5 device/driver/feature unavailable, 6 empty or collapsed result\n"
          "(nothing written), 130 interrupted.");
      auto apply = add_clean_options(cmd);
      auto intrinsics = add_intrinsics_options(cmd);
      add_report_option(cmd);
      c->preview = add_preview_option(cmd);
      return [c, apply, intrinsics] { return run_capture(*c, apply, intrinsics); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif
