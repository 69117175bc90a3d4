#pragma once
// Private: the OpenCV side of SlCapture (shared by the decoders).

#include <opencv2/core.hpp>
#include <vector>

#include "scanclean/drivers/sl_capture.h"

namespace scanclean {

struct SlCapture::Impl {
  SlCaptureInfo info;
  std::vector<cv::Mat> images;       //!< by index (CV_8U or CV_16U, one channel, same size)
  std::vector<int> pattern_indices;  //!< the Gray-code images in generate() order
};

}  // namespace scanclean
