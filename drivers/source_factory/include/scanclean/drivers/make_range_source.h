#pragma once
//! \file make_range_source.h
//! The one factory that knows every concrete RangeSource. Everything else (the pipeline, the
//! commands) works on the RangeSource interface only.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"

namespace scanclean {

//! Options of the sources; each applies only to the kinds named.
struct SourceOptions {
  // Depth images (TUM PNG, mm PNG/PGM/TIFF, NYU raw PGM):
  std::string depth_format = "auto";   //!< "auto", "tum", "mm", "nyu"
  std::optional<Intrinsics> K;         //!< overrides the intrinsics.json sidecar
  std::string noise_model;             //!< "" = by format; "nguyen2012", "structured-light", "none"
  double frame_period_s = 1.0 / 30.0;  //!< timestamps when the file names carry none
  // Recording folders:
  bool recorded_pacing = false;  //!< reproduce the recorded frame timing (default: fast)
  // OpenNI2 (live devices, .oni, vsensor://):
  bool depth_100um = false;      //!< live devices: 0.1 mm depth units
  int disconnect_timeouts = 30;  //!< consecutive timeouts reported as a disconnect (0 = never)
  // Structured-light captures:
  std::filesystem::path sl_calibration;  //!< calibration file override; empty = beside capture
  int sl_projector_width = 0, sl_projector_height = 0;  //!< > 0 override the projector size
};

//! Builds (does not open) the source for
//!   "openni2://" or "openni2://<device uri>"  a live OpenNI2 device,
//!   "vsensor://<abs folder>?..."                the project's virtual OpenNI2 sensor,
//!   "<file>.oni"                                an OpenNI recording (played through OpenNI2),
//!   "<folder>" with session.json                a recording folder (format v1),
//!   "<folder>" with capture.json / graycode_*   a structured-light capture (or a folder of them),
//!   "<file>.png|.pgm|.tif|.tiff" or a folder of them   depth images,
//!   "file://<path>"                             the same as <path>.
//! \throw OptionError for an unknown scheme (the message lists the known ones) or bad options;
//! InputError for a missing path or one that is no known format (the message lists the
//! accepted formats); UnavailableError for a kind this build leaves out (e.g. "built without
//! SCANCLEAN_WITH_OPENNI2").
std::unique_ptr<RangeSource> make_range_source(const std::string& uri_or_path,
                                               const SourceOptions& options = {});

//! Which kinds this build can open ("recording", "depth-images", "openni2", "structured-light").
std::vector<std::string> available_source_kinds();

//! A few lines describing the accepted sources, for --help texts and error messages.
std::string accepted_sources_help();

}  // namespace scanclean
