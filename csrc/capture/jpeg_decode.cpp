#include "capture/jpeg_decode.hpp"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <csetjmp>
#include <cstdio>  // jpeglib.h uses FILE without including it
#include <cstring>

extern "C" {
#include <jpeglib.h>
}

namespace hw {

namespace {

struct CountingErrors {
    jpeg_error_mgr pub;  // first member: libjpeg hands the callbacks &pub as cinfo->err
    std::jmp_buf fatal;
    char first[JMSG_LENGTH_MAX];
};

// A fatal error goes back to run_libjpeg's setjmp; libjpeg's default handler would end the process.
void on_fatal(j_common_ptr cinfo) { std::longjmp(reinterpret_cast<CountingErrors *>(cinfo->err)->fatal, 1); }

// Level -1 is a warning: counted, the first one's text kept. Levels 0 and up are trace messages, which
// libjpeg's default trace level 0 does not print either.
void on_message(j_common_ptr cinfo, int level) {
    auto *err = reinterpret_cast<CountingErrors *>(cinfo->err);
    if (level >= 0) return;
    if (err->pub.num_warnings++ == 0) err->pub.format_message(cinfo, err->first);
}

bool has_exif(j_decompress_ptr cinfo) {
    for (jpeg_saved_marker_ptr m = cinfo->marker_list; m != nullptr; m = m->next)
        if (m->marker == JPEG_APP0 + 1 && m->data_length >= 6 && std::memcmp(m->data, "Exif\0\0", 6) == 0)
            return true;
    return false;
}

// Decodes `data` into `gray`, or, when `opencv_pixels` comes back true, only reads its coefficients. Reads
// on to the end-of-image marker either way: data left before it is a warning too. False on a fatal error.
// Nothing here has a destructor that the longjmp from on_fatal could skip.
bool run_libjpeg(const std::vector<uchar> &data, CountingErrors &err, cv::Mat &gray, bool &opencv_pixels) {
    jpeg_decompress_struct cinfo;
    std::memset(&cinfo, 0, sizeof cinfo);  // jpeg_destroy_decompress is safe on it if creating it fails
    cinfo.err = jpeg_std_error(&err.pub);
    err.pub.error_exit = on_fatal;
    err.pub.emit_message = on_message;
    err.first[0] = '\0';
    if (setjmp(err.fatal) != 0) {
        jpeg_destroy_decompress(&cinfo);
        return false;
    }
    jpeg_create_decompress(&cinfo);
    jpeg_mem_src(&cinfo, data.data(), static_cast<unsigned long>(data.size()));
    jpeg_save_markers(&cinfo, JPEG_APP0 + 1, 6);  // enough of each APP1 segment to tell an Exif one
    jpeg_read_header(&cinfo, TRUE);
    opencv_pixels = has_exif(&cinfo) || (cinfo.num_components != 1 && cinfo.num_components != 3);
    if (opencv_pixels) {
        jpeg_read_coefficients(&cinfo);  // all of the entropy-coded data, hence every warning; no pixels
    } else {
        cinfo.out_color_space = JCS_GRAYSCALE;  // what OpenCV asks for with IMREAD_GRAYSCALE
        jpeg_start_decompress(&cinfo);
        gray.create(static_cast<int>(cinfo.output_height), static_cast<int>(cinfo.output_width), CV_8UC1);
        JSAMPROW rows[16];
        while (cinfo.output_scanline < cinfo.output_height) {
            const JDIMENSION from = cinfo.output_scanline;
            const JDIMENSION n = std::min<JDIMENSION>(16, cinfo.output_height - from);
            for (JDIMENSION k = 0; k < n; ++k) rows[k] = gray.ptr(static_cast<int>(from + k));
            jpeg_read_scanlines(&cinfo, rows, n);
        }
    }
    jpeg_finish_decompress(&cinfo);
    jpeg_destroy_decompress(&cinfo);
    return true;
}

} // namespace

JpegDecode decode_jpeg_gray(const std::vector<uchar> &data) {
    JpegDecode out;
    CountingErrors err;
    bool opencv_pixels = false;
    const bool decoded = run_libjpeg(data, err, out.gray, opencv_pixels);
    out.warnings = static_cast<int>(err.pub.num_warnings);
    if (out.warnings > 0) out.first_warning = err.first;
    if (!decoded)
        out.gray.release();
    else if (opencv_pixels)
        out.gray = cv::imdecode(data, cv::IMREAD_GRAYSCALE);
    return out;
}

} // namespace hw
