// jpeg_decode.hpp - a JPEG file decoded to gray by libjpeg, its warnings counted instead of printed.
//
// libjpeg decodes corrupt entropy-coded data (a flipped bit, a damaged sector) into grey blocks and only
// warns ("Corrupt JPEG data: 1143 extraneous bytes before marker 0xd9") on stderr; cv::imdecode hands back
// the damaged image as if whole. Decoding here, with an error manager that counts the warnings, lets the
// image folder source skip such a file in the one decode it pays for anyway. A warning is the same verdict
// as app/decode_errors.py's jpeg_warnings for the Python readers (whatever libjpeg writes to stderr there).
#pragma once

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace hw {

struct JpegDecode {
    cv::Mat gray;               // 8-bit gray; empty when libjpeg gave up on the data (a fatal error)
    int warnings = 0;           // libjpeg's warnings while decoding: more than 0 = the image is damaged
    std::string first_warning;  // the first one's text, as libjpeg would have printed it
};

// The bytes of a JPEG file decoded to the same pixels as cv::imdecode(data, cv::IMREAD_GRAYSCALE): libjpeg
// with gray output for 1- and 3-component images. An image with an Exif segment (OpenCV turns it by its
// orientation) or with 4 components (CMYK, converted by OpenCV's own formula) is read by libjpeg to its end
// for the warnings, then decoded by cv::imdecode.
JpegDecode decode_jpeg_gray(const std::vector<uchar> &data);

} // namespace hw
