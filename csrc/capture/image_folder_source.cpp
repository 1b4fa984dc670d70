#include "capture/image_folder_source.hpp"

#include "base/errors.hpp"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <filesystem>

namespace hw {

namespace fs = std::filesystem;

ImageFolderSource::ImageFolderSource(const std::string &path, double fps, SourceSize size)
    : path_(path), fps_(fps), size_(size) {
    std::error_code ec;
    if (!fs::is_directory(path, ec)) throw SourceError("image folder " + path + ": no such folder");
    if (!(fps > 0)) throw SourceError("image folder " + path + ": fps must be positive (give --fps)");
    for (const auto &e : fs::directory_iterator(path, ec))
        if (e.is_regular_file() && is_image_file_name(e.path().string())) files_.push_back(e.path().string());
    std::sort(files_.begin(), files_.end());
    if (files_.empty())
        throw SourceError("image folder " + path + ": contains no images (.png .jpg .bmp .pgm .tif)");
}

ReadStatus ImageFolderSource::read(Frame &out) {
    if (next_ >= files_.size()) return ReadStatus::End;
    const size_t i = next_++;
    cv::Mat img = cv::imread(files_[i], cv::IMREAD_GRAYSCALE);
    if (img.empty()) return ReadStatus::DecodeError;
    if (img.cols != size_.width || img.rows != size_.height) return ReadStatus::SizeChanged;
    out.gray = img;
    out.t_s = double(i) / fps_;  // media time of the frame at the given rate
    out.number = int64_t(i);
    return ReadStatus::Ok;
}

} // namespace hw
