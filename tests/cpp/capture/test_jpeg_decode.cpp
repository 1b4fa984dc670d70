// decode_jpeg_gray: a whole JPEG decodes to cv::imdecode's pixels without a warning; flipped bits in its
// entropy-coded data draw libjpeg's "Corrupt JPEG data" warning; an Exif orientation is applied as OpenCV does;
// bytes that are no JPEG give no image and no crash.
#include "capture/jpeg_decode.hpp"

#include <doctest/doctest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <string>
#include <vector>

namespace {

std::vector<uchar> noise_jpeg(int type) {
    cv::Mat img(240, 320, type);
    cv::RNG rng(7);
    rng.fill(img, cv::RNG::UNIFORM, 0, 256);
    std::vector<uchar> buf;
    REQUIRE(cv::imencode(".jpg", img, buf));
    return buf;
}

size_t differing_pixels(const cv::Mat &a, const cv::Mat &b) {
    REQUIRE(a.size() == b.size());
    return size_t(cv::countNonZero(a != b));
}

// An APP1 segment holding only an Exif orientation (tag 0x0112, one SHORT), put right after the start-of-image.
std::vector<uchar> with_exif_orientation(const std::vector<uchar> &jpeg, uchar orientation) {
    const std::vector<uchar> app1 = {0xFF, 0xE1, 0x00, 34, 'E', 'x', 'i', 'f', 0, 0,  // length 34: all after FF E1
                                     'I', 'I', 42, 0, 8, 0, 0, 0,                   // little-endian TIFF, IFD at 8
                                     1, 0,                                          // one entry
                                     0x12, 0x01, 3, 0, 1, 0, 0, 0, orientation, 0, 0, 0,
                                     0, 0, 0, 0};                                   // no next IFD
    std::vector<uchar> out(jpeg.begin(), jpeg.begin() + 2);
    out.insert(out.end(), app1.begin(), app1.end());
    out.insert(out.end(), jpeg.begin() + 2, jpeg.end());
    return out;
}

} // namespace

TEST_CASE("whole gray and colour JPEGs: no warning, the same pixels as cv::imdecode") {
    for (int type : {CV_8UC1, CV_8UC3}) {
        const std::vector<uchar> jpeg = noise_jpeg(type);
        const hw::JpegDecode d = hw::decode_jpeg_gray(jpeg);
        CHECK(d.warnings == 0);
        CHECK(d.first_warning.empty());
        REQUIRE(d.gray.type() == CV_8UC1);
        CHECK(d.gray.cols == 320);
        CHECK(d.gray.rows == 240);
        CHECK(differing_pixels(d.gray, cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE)) == 0);
    }
}

TEST_CASE("one flipped bit in the entropy-coded data: libjpeg's corrupt-data warning, counted") {
    std::vector<uchar> jpeg = noise_jpeg(CV_8UC1);
    const uchar sos[] = {0xFF, 0xDA};
    const size_t scan = size_t(std::search(jpeg.begin(), jpeg.end(), sos, sos + 2) - jpeg.begin());
    REQUIRE(scan + 2000 < jpeg.size());
    jpeg[scan + 1000] ^= 0x10;
    REQUIRE(!cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE).empty());  // OpenCV alone hands back an image
    const hw::JpegDecode d = hw::decode_jpeg_gray(jpeg);
    CHECK(d.warnings >= 1);
    CHECK(d.first_warning.rfind("Corrupt JPEG data", 0) == 0);
    CHECK(!d.gray.empty());  // decoded all the same, with grey blocks: the caller skips it by the count
}

TEST_CASE("an Exif orientation of 3 (upside down): turned by 180 degrees, as cv::imdecode turns it") {
    const std::vector<uchar> plain = noise_jpeg(CV_8UC1);
    const std::vector<uchar> turned = with_exif_orientation(plain, 3);
    const hw::JpegDecode d = hw::decode_jpeg_gray(turned);
    CHECK(d.warnings == 0);
    cv::Mat upside_down;
    cv::flip(cv::imdecode(plain, cv::IMREAD_GRAYSCALE), upside_down, -1);
    CHECK(differing_pixels(d.gray, upside_down) == 0);
    CHECK(differing_pixels(d.gray, cv::imdecode(turned, cv::IMREAD_GRAYSCALE)) == 0);
}

TEST_CASE("bytes that are no JPEG: no image, returned (libjpeg's fatal error does not end the process)") {
    const std::vector<uchar> text = {'n', 'o', 't', ' ', 'a', ' ', 'j', 'p', 'e', 'g'};
    CHECK(hw::decode_jpeg_gray(text).gray.empty());
    std::vector<uchar> cut = noise_jpeg(CV_8UC1);
    cut.resize(200);  // inside the headers
    CHECK(hw::decode_jpeg_gray(cut).gray.empty());
}
