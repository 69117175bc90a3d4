#pragma once
//! `--preview FILE.png` of filter, replay, capture and sl decode: what the filter did, in one
//! picture. Two panels from the same viewpoint: left the filter's input (grey, shaded by its
//! normals when it has them) with the removed points marked in magenta on top; right the
//! filtered points coloured by their "displacement" attribute (signed move along the normal,
//! blue - grey - red over +-the 98th percentile of |displacement|), under a colour bar in
//! millimetres. Below them the same two panels, magnified 3x about the centre (framed in the
//! whole view), where the smoothing shows. Rendered with OpenCV (z-buffered square splats); OpenCV
//! stays in preview.cpp.

#include <CLI/CLI.hpp>
#include <filesystem>
#include <memory>
#include <string>

#include "scanclean/core/point_cloud.h"

namespace scanclean::app {

//! The viewpoint. kCamera: the points are in a camera frame (x right, y down, z forward; depth
//! frames, structured light): a pinhole view from the origin. kAuto: an orthographic view along
//! the axis of the cloud's smallest extent, from the side most output normals face.
enum class PreviewView { kAuto, kCamera };

struct PreviewOptions {
  PreviewView view = PreviewView::kAuto;
  int panel_width = 720;   //!< pixels
  int panel_height = 540;  //!< pixels
  std::string title;       //!< top line, e.g. the command and the input
};

//! What the picture shows (for the summary).
struct PreviewFacts {
  double range_m = 0;       //!< colour range: +-range_m
  double median_abs_m = 0;  //!< median |displacement|
  std::size_t before = 0, after = 0, removed = 0;
};

//! Adds --preview FILE.png to `cmd`; the returned string holds the path ("" = none).
std::shared_ptr<std::string> add_preview_option(CLI::App& cmd);

//! Checks the preview path before any work: .png, existing writable folder, not a folder.
//! Notes it as an output of the run's report. \throw OptionError, IoError.
void check_preview_path(const std::string& command, const std::string& path);

//! Renders `before` (the filter's input), `after` (its output, with normals and the
//! "displacement" attribute) and `removed` (its outliers) and writes the PNG atomically.
//! \throw IoError.
PreviewFacts write_preview(const std::filesystem::path& png, const PointCloud& before,
                           const PointCloud& after, const PointCloud& removed,
                           const PreviewOptions& options);

//! Adds "preview" to a summary-like sink: "<path> (colour range +-X mm, median |d| Y mm)".
std::string preview_summary_text(const std::string& path, const PreviewFacts& facts);

}  // namespace scanclean::app
