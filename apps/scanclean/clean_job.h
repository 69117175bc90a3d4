#pragma once
//! The capture-and-clean job shared by `replay` and `capture`: the frame-to-points and filter
//! options, the frame range, and the run (source -> points -> robust filter -> files, with the
//! summary). One home, so that an option or a check is added once for both commands.

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <string>

#include "scanclean/core/range_source.h"
#include "scanclean/drivers/make_range_source.h"
#include "scanclean/pipeline/pipeline.h"

namespace scanclean::app {

//! Adds the frame-to-points and filter options (filter_options_cli.h, with the depth-frame
//! defaults: --scale-gamma 0, --displacement-sigma 0) to `cmd`; the returned function copies the
//! parsed values into PipelineOptions.
std::function<void(PipelineOptions&)> add_clean_options(CLI::App& cmd);

//! Adds --fx --fy --cx --cy (depth images carry no intrinsics). The returned function puts them
//! into SourceOptions for `source`: all four or none, and only for depth images (an .oni file, a
//! device URI, a recording folder or a structured-light capture carries its own; giving them
//! there is refused rather than silently ignored). 	hrow OptionError naming the options.
std::function<void(const std::string& source, SourceOptions&)> add_intrinsics_options(
    CLI::App& cmd);

//! Parses "A:B", "A:", ":B" or "N" (delivery positions from 0, B exclusive) into the options.
//! \throw OptionError naming --frames.
void parse_frame_range(const std::string& text, PipelineOptions& options);

//! Checks the outputs (clean output and --outliers) before anything is read: known format,
//! existing writable folder, not equal to `input` (when it is a file) nor to each other, and
//! --outliers not combined with --raw. \throw OptionError, IoError.
void check_clean_outputs(const std::string& command, const PipelineOptions& options,
                         const std::filesystem::path& input, const std::filesystem::path& output,
                         const std::filesystem::path& outliers);

//! What a live run adds to the job: the latest cleaned window at a fixed path, and the
//! recording folder (for the summary).
struct LiveOutputs {
  std::filesystem::path latest;  //!< rewritten atomically after every cleaned window ("" = none)
  std::filesystem::path record;  //!< the --record folder, if any (every delivered frame is in it)
};

//! Runs the job on `source` (not yet opened) and writes the outputs (the clean cloud and the
//! outliers of a window are committed together or not at all). Returns the exit code: 0; 130
//! after SIGINT (what was captured is written); 3 on a source error or when no frame was read;
//! 5 when the source kept disconnecting until the --reconnect budget was used up;
//! 6 when a window's result is empty or collapsed to one point although its input was not
//! (that window is not written).
//! `preview`: --preview FILE.png of the first window (preview.h), "" = none.
int run_clean_job(const std::string& command, RangeSource& source, PipelineOptions options,
                  const std::filesystem::path& output, const std::filesystem::path& outliers,
                  const std::string& preview = {}, const LiveOutputs& live = {});

}  // namespace scanclean::app
