#include "scanclean/drivers/make_range_source.h"

#include <algorithm>
#include <cctype>
#include <string>
#include <system_error>

#include "scanclean/core/errors.h"
#include "scanclean/replay/depth_image_source.h"
#include "scanclean/replay/organized_cloud_source.h"
#include "scanclean/replay/recording_format.h"
#include "scanclean/replay/replay_source.h"
#ifdef SCANCLEAN_HAVE_OPENNI2
#include "scanclean/drivers/openni2_source.h"
#endif
#ifdef SCANCLEAN_HAVE_SL
#include "scanclean/drivers/sl_capture.h"
#include "scanclean/drivers/structured_light_source.h"
#endif

namespace scanclean {
namespace {

namespace fs = std::filesystem;

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

bool is_depth_image_extension(const fs::path& p) {
  const std::string e = lower(p.extension().string());
  return e == ".png" || e == ".pgm" || e == ".tif" || e == ".tiff";
}

std::unique_ptr<RangeSource> openni2_source(const std::string& uri, const SourceOptions& o) {
#ifdef SCANCLEAN_HAVE_OPENNI2
  OpenNI2Options oo;
  oo.depth_100um = o.depth_100um;
  oo.disconnect_timeouts = o.disconnect_timeouts;
  validate(oo);
  return make_openni2_source(uri, oo);
#else
  (void)o;
  throw UnavailableError("cannot open \"" + uri +
                         "\": built without SCANCLEAN_WITH_OPENNI2 (reconfigure with "
                         "-DSCANCLEAN_WITH_OPENNI2=ON and libopenni2-dev installed)");
#endif
}

bool looks_like_sl(const fs::path& p) {
#ifdef SCANCLEAN_HAVE_SL
  if (is_structured_light_capture(p)) return true;
  std::error_code ec;
  return fs::is_directory(p, ec) && !find_structured_light_captures(p).empty();
#else
  (void)p;
  return false;
#endif
}

//! A folder with .pcd or .ply files: a sequence of organized clouds.
bool holds_cloud_files(const fs::path& p) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(p, ec)) {
    const std::string x = lower(e.path().extension().string());
    if ((x == ".pcd" || x == ".ply") && e.is_regular_file(ec)) return true;
  }
  return false;
}

std::unique_ptr<RangeSource> sl_source(const fs::path& p, const SourceOptions& o) {
#ifdef SCANCLEAN_HAVE_SL
  SlOptions so;
  so.calibration = o.sl_calibration;
  so.projector_width = o.sl_projector_width;
  so.projector_height = o.sl_projector_height;
  validate(so);
  return make_structured_light_source(p, so);
#else
  (void)o;
  throw UnavailableError(p.string() +
                         ": structured-light captures need the sl module, which this "
                         "build leaves out");
#endif
}

std::unique_ptr<RangeSource> depth_images(const fs::path& p, const SourceOptions& o) {
  DepthImageOptions d;
  d.format = o.depth_format;
  d.K = o.K;
  d.noise_model = o.noise_model;
  d.frame_period_s = o.frame_period_s;
  validate(d);
  return make_depth_image_source(p, d);
}

}  // namespace

std::vector<std::string> available_source_kinds() {
  std::vector<std::string> k{"recording", "depth-images"};
#ifdef SCANCLEAN_HAVE_OPENNI2
  k.push_back("openni2");
#endif
#ifdef SCANCLEAN_HAVE_SL
  k.push_back("structured-light");
#endif
  return k;
}

std::string accepted_sources_help() {
  std::string s =
      "a recording folder (session.json, frames.csv, depth/*.png), depth images (.png .pgm "
      ".tif .tiff: a file or a folder; TUM, millimetre or NYU raw), organized point clouds (.pcd "
      ".ply with a grid: a file or a folder, e.g. a PCL grabber sequence)";
#ifdef SCANCLEAN_HAVE_SL
  s += ", a structured-light capture folder (capture.json or graycode_*.png)";
#endif
#ifdef SCANCLEAN_HAVE_OPENNI2
  s += ", an OpenNI .oni file, openni2:// (first sensor), openni2://<device uri> or "
       "vsensor://<absolute recording folder>";
#else
  s += " (OpenNI2 sources: .oni, openni2://, vsensor:// need a build with "
       "SCANCLEAN_WITH_OPENNI2)";
#endif
  return s;
}

std::unique_ptr<RangeSource> make_range_source(const std::string& uri_or_path,
                                               const SourceOptions& options) {
  if (uri_or_path.empty()) throw OptionError("source: empty; give " + accepted_sources_help());
  std::string target = uri_or_path;
  const auto scheme_end = target.find("://");
  if (scheme_end != std::string::npos) {
    const std::string scheme = lower(target.substr(0, scheme_end));
    if (scheme == "openni2" || scheme == "vsensor") return openni2_source(target, options);
    if (scheme != "file")
      throw OptionError("source \"" + uri_or_path + "\": unknown scheme \"" + scheme +
                        "://\"; known schemes: openni2://, vsensor://, file:// (or a plain path)");
    target = target.substr(scheme_end + 3);
  }
  const fs::path p(target);
  std::error_code ec;
  const bool exists = fs::exists(p, ec);
  if (lower(p.extension().string()) == ".oni") {
    if (!exists) throw InputError(target, "open", "no such file (an OpenNI .oni recording)");
    return openni2_source(target, options);
  }
  if (!exists)
    throw InputError(target, "open", "no such file or folder; expected " + accepted_sources_help());
  if (fs::is_directory(p, ec)) {
    if (is_recording_folder(p))
      return make_replay_source(
          p, options.recorded_pacing ? Pacing::kRecorded : Pacing::kAsFastAsPossible);
    if (looks_like_sl(p)) return sl_source(p, options);
    if (holds_cloud_files(p)) return make_organized_cloud_source(p);
    try {
      return depth_images(p, options);
    } catch (const InputError& e) {
      throw InputError(target, "folder",
                       "no known source format here (" + std::string(e.what()) + "); expected " +
                           accepted_sources_help());
    }
  }
  const std::string name = lower(p.filename().string());
  if (name == "session.json") return make_range_source(p.parent_path().string(), options);
  if (name == "capture.json") return sl_source(p.parent_path(), options);
  if (is_depth_image_extension(p)) return depth_images(p, options);
  if (const auto e = lower(p.extension().string()); e == ".pcd" || e == ".ply")
    return make_organized_cloud_source(p);
  throw InputError(target, "file",
                   "not a known source format (extension \"" + p.extension().string() +
                       "\"); expected " + accepted_sources_help());
}

}  // namespace scanclean
