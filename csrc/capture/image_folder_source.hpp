// image_folder_source.hpp - a folder of still images played as a video at a given frame rate.
#pragma once

#include "capture/frame_source.hpp"

#include <vector>

namespace hw {

class ImageFolderSource final : public FrameSource {
public:
    // Lists the images (sorted by name); throws SourceError for a missing or empty folder.
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
