// frame_source.hpp - where frames come from: cameras, recordings, frames pushed from Python.
//
// A source hands out 8-bit gray frames (colour converted once, here) with a capture timestamp and a
// frame number. It never throws while running: trouble is a ReadStatus that the loop turns into a
// health event, and a live source that is lost is reopened by the loop with back-off.
#pragma once

#include "base/types.hpp"

#include <memory>
#include <string>

namespace hw {

enum class ReadStatus {
    Ok,           // `out` holds a frame
    Again,        // nothing yet (push source waiting); call again
    DecodeError,  // a frame could not be decoded and was skipped
    SizeChanged,  // a frame of another size than the configured one was skipped
    Lost,         // a live device stopped delivering; reopen() it
    End           // a recording has no more frames
};

class FrameSource {
public:
    virtual ~FrameSource() = default;
    virtual ReadStatus read(Frame &out) = 0;
    // Live sources: try to open the device again after a loss. Returns true when it delivers again.
    virtual bool reopen() { return false; }
    virtual bool live() const { return false; }
    // Recordings: the loop waits for the consumer instead of dropping results, so a replay is complete
    // and deterministic. Cameras and pushed frames: the newest result wins.
    virtual bool paced_by_consumer() const { return false; }
    // Unblocks a read() waiting in another thread (push source); the loop calls it on stop.
    virtual void interrupt() {}
    virtual std::string describe() const = 0;
};

// Parameters every source shares: the size the pipeline expects.
struct SourceSize {
    int width = 640, height = 480;
};

// Builds a source from its JSON description:
//   {"kind": "v4l2", "device": "/dev/video0" | 0, "width": 640, "height": 480, "fps": 30,
//    "pixel_format": "YUYV", "wait_for_device": false}
//   {"kind": "firewire", "index": 0 | "guid": "0x0814436102a3e5f1", "width", "height", "fps", "wait_for_device"}
//   {"kind": "video", "path": "drive.mp4"}
//   {"kind": "folder", "path": "frames/", "fps": 20}
//   {"kind": "push"}
// Opens it at once; throws SourceError naming the device or file and what to do when it cannot.
// `size` is the frame size of the configured camera; frames of another size are skipped (SizeChanged).
std::unique_ptr<FrameSource> open_source(const std::string &json_text, SourceSize size, int push_capacity);

// True for the still-image file names an image folder plays (.png .jpg .bmp .pgm .tif ...).
bool is_image_file_name(const std::string &path);

// Converts any 8-bit 1/3/4-channel image to gray (a shallow copy if it already is gray).
cv::Mat to_gray(const cv::Mat &img);

} // namespace hw
