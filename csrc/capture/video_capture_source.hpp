// video_capture_source.hpp - sources read through cv::VideoCapture: V4L2 and FireWire (IEEE 1394,
// libdc1394) cameras, and video files (FFmpeg).
#pragma once

#include "capture/frame_source.hpp"

#include <opencv2/videoio.hpp>

namespace hw {

struct CameraSpec {
    int api = cv::CAP_V4L2;      // cv::CAP_V4L2 or cv::CAP_FIREWIRE
    std::string device;          // V4L2 path ("/dev/video0"); empty = use index
    int index = 0;               // device index (V4L2 /dev/videoN, or the n-th FireWire camera)
    std::string guid;            // FireWire: pick the camera with this GUID (hex), empty = by index
    int width = 640, height = 480;
    double fps = 30.0;
    std::string pixel_format;    // V4L2 FOURCC such as "YUYV", "MJPG", "GREY"; empty = driver default
};

// A live camera. Timestamps come from the monotonic clock when the frame is read.
class CameraSource final : public FrameSource {
public:
    CameraSource(CameraSpec spec, SourceSize size);
    // Throws SourceError naming the device when it cannot be opened.
    void open_or_throw();
    ReadStatus read(Frame &out) override;
    bool reopen() override;
    bool live() const override { return true; }
    std::string describe() const override;

private:
    bool try_open();
    CameraSpec spec_;
    SourceSize size_;
    cv::VideoCapture cap_;
    cv::Mat bgr_;
    int64_t next_number_ = 0;
};

// A recorded video file. Timestamps are media time (s from the start of the file).
class VideoFileSource final : public FrameSource {
public:
    VideoFileSource(const std::string &path, SourceSize size);
    ReadStatus read(Frame &out) override;
    std::string describe() const override { return "video " + path_; }
    bool paced_by_consumer() const override { return true; }

private:
    std::string path_;
    SourceSize size_;
    cv::VideoCapture cap_;
    cv::Mat bgr_;
    double fps_ = 0.0;
    int64_t frame_count_ = 0;   // as the container says; 0 if unknown
    int64_t next_number_ = 0;
    bool first_concealed_ = false;  // FFmpeg logged errors while the constructor decoded frame 0
};

} // namespace hw
