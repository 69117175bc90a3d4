// scanclean record: raw frames from any source to a crash-safe recording folder (format v1), or
// to an .oni file through openni::Recorder (OpenNI2 device sources only).

#if defined(SCANCLEAN_HAVE_SOURCES) && defined(SCANCLEAN_HAVE_REPLAY) && \
    defined(SCANCLEAN_HAVE_PIPELINE)

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/progress.h"
#include "scanclean/drivers/make_range_source.h"
#include "scanclean/interrupt.h"
#include "scanclean/pipeline/acquisition.h"
#include "scanclean/replay/recording_format.h"
#include "scanclean/replay/recording_source.h"
#include "scanclean/summary.h"
#ifdef SCANCLEAN_HAVE_OPENNI2
#include "scanclean/drivers/openni2_source.h"
#endif

namespace scanclean::app {

namespace {

using Clock = std::chrono::steady_clock;

struct RecordCommandOptions {
  std::string source;
  std::string output;
  std::uint64_t frames = 0;
  double seconds = 0;
};

// vsensor://<recording folder>[?...] without loop=1: the virtual sensor ends with the folder.
bool finite_vsensor(const std::string& uri) {
  const std::string scheme = "vsensor://";
  if (uri.rfind(scheme, 0) != 0) return false;
  const std::string rest = uri.substr(scheme.size());
  const auto q = rest.find('?');
  const std::string folder = rest.substr(0, q);
  const std::string query = q == std::string::npos ? "" : "&" + rest.substr(q + 1) + "&";
  if (query.find("&loop=1&") != std::string::npos) return false;
  return is_recording_folder(folder);
}

bool ends_with_oni(const std::string& s) {
  if (s.size() < 4) return false;
  std::string e = s.substr(s.size() - 4);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char ch) { return std::tolower(ch); });
  return e == ".oni";
}

// The one acquisition loop (acquire) over `source`, which records every frame it delivers.
int record_frames(const RecordCommandOptions& c, RangeSource& source, const std::string& what,
                  bool idle_ends) {
  install_sigint_handler();
  const auto start = Clock::now();
  source.open();
  const SourceInfo info = source.info();
  for (const auto& w : info.warnings)
    std::fprintf(stderr, "scanclean record: warning: %s\n", w.c_str());
  std::unique_ptr<Progress> bar;
  if (c.frames > 0) bar = std::make_unique<Progress>("record: frames", c.frames);
  AcquisitionOptions ao;
  ao.max_frames = c.frames;
  ao.max_seconds = c.seconds;
  ao.timeout = std::chrono::milliseconds(idle_ends ? 100 : 1000);
  // A manual-paced virtual sensor at the end of its data never sends again: 5 s without a
  // frame end its recording.
  if (idle_ends) ao.max_consecutive_timeouts = 50;
  ao.keep_going = [] { return !interrupted(); };
  const AcquisitionStats st = acquire(source, ao, [&](RangeFrame&, std::uint64_t) {
    if (bar) bar->advance();
  });
  if (bar) bar->finish();
  source.close();  // finalizes the recording
  Summary sum("scanclean record");
  sum.add("source", info.uri + " (" + info.kind + ")");
  sum.add("output", c.output + " (" + what + ")");
  sum.add("stopped",
          std::string(to_string(st.stop)) + (st.message.empty() ? "" : ": " + st.message));
  sum.add_count("frames written", st.frames_read);
  sum.add_count("dropped frames (index gaps)", st.dropped_frames);
  sum.add_count("timeouts", st.timeouts);
  sum.add("total", std::chrono::duration<double>(Clock::now() - start).count(), 2, "s");
  sum.print();
  return st.stop == StopReason::kInterrupted ? static_cast<int>(ExitCode::kInterrupted) : 0;
}

int record_to_oni(const RecordCommandOptions& c) {
#ifdef SCANCLEAN_HAVE_OPENNI2
  if (c.source.rfind("openni2://", 0) != 0 && c.source.rfind("vsensor://", 0) != 0)
    throw OptionError(
        "record: an .oni output needs an OpenNI2 device source (openni2:// or "
        "vsensor://), got \"" +
        c.source + "\"; record other sources to a folder (an OUT without .oni)");
  auto source = make_oni_recording_source(c.source, c.output);
  return record_frames(c, *source, ".oni, openni::Recorder", c.source.rfind("vsensor://", 0) == 0);
#else
  (void)c;
  throw UnavailableError("record: .oni output needs OpenNI2; built without SCANCLEAN_WITH_OPENNI2");
#endif
}

int record_to_folder(const RecordCommandOptions& c) {
  auto source = make_recording_source(make_range_source(c.source), c.output);
  return record_frames(c, *source, "recording folder v1", false);
}

const CommandRegistrar kRegistrar{{
    "record",
    "Record raw frames: to a crash-safe recording folder, or to .oni (OpenNI2 devices)",
    44,
    [](CLI::App& cmd) {
      auto c = std::make_shared<RecordCommandOptions>();
      cmd.add_option("--source", c->source,
                     "Source URI: openni2://, openni2://<device uri>, vsensor://<folder>, or a "
                     "path (recording folder, depth images, .oni, structured-light capture)")
          ->required();
      auto* f =
          cmd.add_option("--frames", c->frames, "Stop after N frames")->check(positive_number());
      auto* s =
          cmd.add_option("--seconds", c->seconds, "Stop after S seconds")->check(positive_number());
      (void)f;
      (void)s;
      cmd.add_option("output", c->output,
                     "OUT.oni (openni::Recorder, OpenNI2 sources only) or a new folder "
                     "(recording format v1: session.json, frames.csv, depth/*.png; a killed "
                     "recording stays readable up to its last complete frame)")
          ->required();
      return [c]() -> int {
        if (c->frames == 0 && c->seconds <= 0 && c->source.find("://") != std::string::npos &&
            !finite_vsensor(c->source))
          throw OptionError(
              "record: give --frames N or --seconds S for a live source (a vsensor:// recording "
              "folder without loop=1 ends by itself)");
        return ends_with_oni(c->output) ? record_to_oni(*c) : record_to_folder(*c);
      };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif
