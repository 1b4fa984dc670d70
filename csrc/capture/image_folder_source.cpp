#include "capture/image_folder_source.hpp"

#include "base/errors.hpp"
#include "capture/jpeg_decode.hpp"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace hw {

namespace fs = std::filesystem;

static std::string lower_extension(const std::string &path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}

static bool is_jpeg_extension(const std::string &ext) { return ext == ".jpg" || ext == ".jpeg"; }

// libjpeg and libpng decode a file cut short (a copy interrupted, a card pulled) into an image whose lower
// part is grey, and imread reports success: a wrong frame, silently. A whole JPEG ends with its end-of-image
// marker (FF D9, within its last 1024 bytes as JPEG_TAIL_BYTES allows) and a whole PNG with its IEND chunk; the same
// rule as app/recording.py's truncation() for the Python readers.
static bool cut_short(const std::vector<uchar> &data, const std::string &ext) {
    const size_t n = data.size();
    auto has_tail = [&](const char *marker, size_t len, size_t tail) {
        const size_t from = n > tail ? n - tail : 0;
        for (size_t i = from; i + len <= n; ++i)
            if (std::equal(marker, marker + len, reinterpret_cast<const char *>(data.data()) + i)) return true;
        return false;
    };
    if (is_jpeg_extension(ext)) return n < 4 || !has_tail("\xff\xd9", 2, 1024);
    if (ext == ".png") return n < 8 || !has_tail("IEND", 4, 32);
    return false;
}

bool natural_name_less(const std::string &a, const std::string &b) {
    auto digit = [](char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; };
    size_t i = 0, j = 0;
    while (i < a.size() && j < b.size()) {
        if (digit(a[i]) && digit(b[j])) {
            size_t ie = i, je = j;
            while (ie < a.size() && digit(a[ie])) ++ie;
            while (je < b.size() && digit(b[je])) ++je;
            size_t iz = i, jz = j;  // leading zeros do not change the number
            while (iz + 1 < ie && a[iz] == '0') ++iz;
            while (jz + 1 < je && b[jz] == '0') ++jz;
            if (ie - iz != je - jz) return ie - iz < je - jz;  // fewer digits: a smaller number
            const int c = a.compare(iz, ie - iz, b, jz, je - jz);
            if (c != 0) return c < 0;
            i = ie;
            j = je;
        } else {
            if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
            ++i;
            ++j;
        }
    }
    if (i < a.size() || j < b.size()) return j < b.size();  // a prefix of the other comes first
    return a < b;
}

ImageFolderSource::ImageFolderSource(const std::string &path, double fps, SourceSize size)
    : path_(path), fps_(fps), size_(size) {
    std::error_code ec;
    if (!fs::is_directory(path, ec)) throw SourceError("image folder " + path + ": no such folder");
    if (!(fps > 0)) throw SourceError("image folder " + path + ": fps must be positive (give --fps)");
    for (const auto &e : fs::directory_iterator(path, ec))
        if (e.is_regular_file() && is_image_file_name(e.path().string())) files_.push_back(e.path().string());
    std::sort(files_.begin(), files_.end(), [](const std::string &x, const std::string &y) {
        return natural_name_less(fs::path(x).filename().string(), fs::path(y).filename().string());
    });
    if (files_.empty())
        throw SourceError("image folder " + path + ": contains no images (.png .jpg .bmp .pgm .tif)");
}

ReadStatus ImageFolderSource::read(Frame &out) {
    if (next_ >= files_.size()) return ReadStatus::End;
    const size_t i = next_++;
    std::ifstream in(files_[i], std::ios::binary);
    std::vector<uchar> data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in.good() && !in.eof()) return ReadStatus::DecodeError;
    const std::string ext = lower_extension(files_[i]);
    if (data.empty() || cut_short(data, ext)) return ReadStatus::DecodeError;
    cv::Mat img;
    if (is_jpeg_extension(ext)) {
        // libjpeg decodes corrupt data into grey blocks and only warns: a warned file is skipped, as the
        // Python readers skip it (app/recording.py's read_image)
        JpegDecode jpeg = decode_jpeg_gray(data);
        if (jpeg.warnings > 0) return ReadStatus::DecodeError;
        img = jpeg.gray;
    } else {
        img = cv::imdecode(data, cv::IMREAD_GRAYSCALE);
    }
    if (img.empty()) return ReadStatus::DecodeError;
    if (img.cols != size_.width || img.rows != size_.height) return ReadStatus::SizeChanged;
    out.gray = img;
    out.t_s = double(i) / fps_;  // media time of the frame at the given rate
    out.number = int64_t(i);
    return ReadStatus::Ok;
}

} // namespace hw
