// scanclean replay: any finite source (recording folder, depth images, .oni, structured-light
// capture, vsensor://) -> points -> robust filter -> PLY/PCD. The job itself is clean_job.h.

#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_FILTER) && \
    defined(SCANCLEAN_HAVE_PIPELINE) && defined(SCANCLEAN_HAVE_SOURCES)

#include <CLI/CLI.hpp>
#include <functional>
#include <memory>
#include <string>

#include "scanclean/clean_job.h"
#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/drivers/make_range_source.h"
#include "scanclean/mesh_handoff.h"
#include "scanclean/pipeline/pipeline.h"
#include "scanclean/preview.h"
#include "scanclean/run_report.h"

namespace scanclean::app {

namespace {

struct ReplayCommandOptions {
  std::string source;
  std::string output;
  std::string outliers;
  std::string frames;
  std::string depth_format = "auto";
  bool paced = false;
  std::shared_ptr<MeshHandoff> mesh;     // --mesh FILE
  std::shared_ptr<std::string> preview;  // --preview FILE.png
};

int run_replay(const ReplayCommandOptions& c, const std::function<void(PipelineOptions&)>& apply,
               const std::function<void(const std::string&, SourceOptions&)>& intrinsics) {
  PipelineOptions o;
  apply(o);
  if (!c.frames.empty()) parse_frame_range(c.frames, o);
  SourceOptions so;
  so.depth_format = c.depth_format;
  so.recorded_pacing = c.paced;
  intrinsics(c.source, so);
  check_clean_outputs("replay", o, c.source, c.output, c.outliers);
  check_mesh_output(*c.mesh, "replay");
  auto source = make_range_source(c.source, so);
  const int rc = run_clean_job("replay", *source, o, c.output, c.outliers, *c.preview);
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
      auto intrinsics = add_intrinsics_options(cmd);
      cmd.add_flag("--paced", c->paced,
                   "Recording folders: reproduce the recorded frame timing (default: as fast as "
                   "possible)");
      auto apply = add_clean_options(cmd);
      c->mesh = add_mesh_option(cmd);
      add_report_option(cmd);
      c->preview = add_preview_option(cmd);
      return [c, apply, intrinsics] { return run_replay(*c, apply, intrinsics); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif
