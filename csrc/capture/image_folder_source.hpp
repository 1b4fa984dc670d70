// image_folder_source.hpp - a folder of still images played as a video at a given frame rate.
#pragma once

#include "capture/frame_source.hpp"

#include <vector>

namespace hw {

// Natural order of file names: runs of digits compare as numbers, so 2.jpg comes before 10.jpg (TuSimple's clips
// are 1.jpg .. 20.jpg; by plain name 10.jpg would play after 1.jpg). Names equal as numbers (01.jpg, 1.jpg) fall
// back to plain order. The same order as app/recording.py's natural_key for the Python readers.
bool natural_name_less(const std::string &a, const std::string &b);

class ImageFolderSource final : public FrameSource {
public:
    // Lists the images in natural order (natural_name_less); throws SourceError for a missing or empty folder.
    ImageFolderSource(const std::string &path, double fps, SourceSize size);
    ReadStatus read(Frame &out) override;
    std::string describe() const override { return "image folder " + path_; }
    bool paced_by_consumer() const override { return true; }
    size_t size() const { return files_.size(); }

private:
    std::string path_;
    double fps_;
    SourceSize size_;
    std::vector<std::string> files_;
    size_t next_ = 0;
};

} // namespace hw
