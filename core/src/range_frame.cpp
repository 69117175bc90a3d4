#include "scanclean/core/range_frame.h"

#include <cmath>
#include <string>

#include "scanclean/core/errors.h"
#include "scanclean/core/range_source.h"

namespace scanclean {

bool Intrinsics::has_distortion() const {
  for (double d : dist)
    if (d != 0.0) return true;
  return false;
}

Intrinsics Intrinsics::from_fov(int width, int height, double hfov_rad, double vfov_rad) {
  if (width <= 0 || height <= 0)
    throw OptionError("intrinsics: image size must be positive, got " + std::to_string(width) +
                      "x" + std::to_string(height));
  if (!(hfov_rad > 0 && hfov_rad < M_PI) || !(vfov_rad > 0 && vfov_rad < M_PI))
    throw OptionError("intrinsics: field of view must be in (0, pi) rad, got " +
                      std::to_string(hfov_rad) + " x " + std::to_string(vfov_rad));
  Intrinsics k;
  k.width = width;
  k.height = height;
  k.fx = width / (2.0 * std::tan(hfov_rad / 2.0));
  k.fy = height / (2.0 * std::tan(vfov_rad / 2.0));
  k.cx = width / 2.0;
  k.cy = height / 2.0;
  k.source = "fov";
  return k;
}

const char* to_string(ReadStatus status) {
  switch (status) {
    case ReadStatus::kOk:
      return "ok";
    case ReadStatus::kTimeout:
      return "timeout";
    case ReadStatus::kEndOfStream:
      return "end of stream";
    case ReadStatus::kDisconnected:
      return "disconnected";
    case ReadStatus::kError:
      return "error";
  }
  return "unknown";
}

}  // namespace scanclean
