#include "capture/video_capture_source.hpp"

#include "base/errors.hpp"
#include "base/stopwatch.hpp"

#include <atomic>
#include <cstdarg>
#include <dlfcn.h>
#include <filesystem>

namespace hw {

namespace fs = std::filesystem;

namespace {

// FFmpeg conceals a damaged frame (fills the regions it cannot decode) and only says so in its log. Its
// messages of level error or worse (AV_LOG_ERROR 16) are counted through its log callback, in the
// libavutil that OpenCV's videoio already loaded (looked up by name, so the build needs no FFmpeg headers);
// a frame during whose read the count rose is a concealed frame. The count is process-wide, as FFmpeg's log.
constexpr int kAvLogError = 16;
std::atomic<long long> g_ffmpeg_errors{0};

void count_ffmpeg_log(void *, int level, const char *, va_list) {
    if (level <= kAvLogError) g_ffmpeg_errors.fetch_add(1, std::memory_order_relaxed);
}

// Set again after every open: OpenCV sets its own callback when it opens a file with OPENCV_FFMPEG_LOGLEVEL set.
void watch_ffmpeg_errors() {
    using SetCallback = void (*)(void (*)(void *, int, const char *, va_list));
    static const SetCallback set = []() -> SetCallback {
        for (const char *name : {"libavutil.so.57", "libavutil.so.58", "libavutil.so.59", "libavutil.so.56"})
            if (void *lib = dlopen(name, RTLD_NOW | RTLD_NOLOAD))
                return reinterpret_cast<SetCallback>(dlsym(lib, "av_log_set_callback"));
        return nullptr;
    }();
    if (set) set(count_ffmpeg_log);
}

} // namespace

// ---------------------------------------------------------------- live cameras

CameraSource::CameraSource(CameraSpec spec, SourceSize size) : spec_(std::move(spec)), size_(size) {}

std::string CameraSource::describe() const {
    const char *bus = spec_.api == cv::CAP_FIREWIRE ? "FireWire camera " : "V4L2 camera ";
    if (!spec_.guid.empty()) return bus + std::string("GUID ") + spec_.guid;
    if (!spec_.device.empty()) return bus + spec_.device;
    return bus + std::to_string(spec_.index);
}

bool CameraSource::try_open() {
    cap_.release();
    if (spec_.api == cv::CAP_FIREWIRE && !spec_.guid.empty()) {
        // libdc1394 cameras are opened by index; find the index whose GUID matches.
        const unsigned long long want = std::stoull(spec_.guid, nullptr, 16);
        for (int i = 0; i < 16; ++i) {
            cv::VideoCapture c(i, cv::CAP_FIREWIRE);
            if (!c.isOpened()) break;
            if ((unsigned long long)c.get(cv::CAP_PROP_GUID) == want) {
                cap_ = std::move(c);
                break;
            }
        }
    } else if (!spec_.device.empty()) {
        if (!fs::exists(spec_.device)) return false;
        cap_.open(spec_.device, spec_.api);
    } else {
        cap_.open(spec_.index, spec_.api);
    }
    if (!cap_.isOpened()) return false;
    if (spec_.pixel_format.size() == 4) {
        const auto &f = spec_.pixel_format;
        cap_.set(cv::CAP_PROP_FOURCC, cv::VideoWriter::fourcc(f[0], f[1], f[2], f[3]));
    }
    cap_.set(cv::CAP_PROP_FRAME_WIDTH, spec_.width);
    cap_.set(cv::CAP_PROP_FRAME_HEIGHT, spec_.height);
    if (spec_.fps > 0) cap_.set(cv::CAP_PROP_FPS, spec_.fps);
    return true;
}

void CameraSource::open_or_throw() {
    if (!try_open()) {
        std::string hint = spec_.api == cv::CAP_FIREWIRE
                               ? "check that the camera is connected and that the user may open /dev/fw*"
                               : "check that the camera is plugged in, that the device exists (ls /dev/video*) "
                                 "and that the user is in the 'video' group";
        throw SourceError(describe() + ": cannot open: " + hint);
    }
}

bool CameraSource::reopen() { return try_open(); }

ReadStatus CameraSource::read(Frame &out) {
    if (!cap_.isOpened() || !cap_.read(bgr_) || bgr_.empty()) return ReadStatus::Lost;
    const double t = monotonic_s();
    if (bgr_.cols != size_.width || bgr_.rows != size_.height) return ReadStatus::SizeChanged;
    out.gray = to_gray(bgr_).clone();
    out.t_s = t;
    out.number = next_number_++;
    return ReadStatus::Ok;
}

// ---------------------------------------------------------------- video files

VideoFileSource::VideoFileSource(const std::string &path, SourceSize size) : path_(path), size_(size) {
    std::error_code ec;
    if (!fs::exists(path, ec)) throw SourceError("video " + path + ": no such file");
    if (fs::is_directory(path, ec))
        throw SourceError("video " + path + ": is a folder; use an image-folder source (kind: folder) for it");
    // FFmpeg would play a single still image as a one-frame video; that is almost always a mistake.
    if (is_image_file_name(path))
        throw SourceError("video " + path + ": is a still image; play a folder of images (kind: folder) or use `headway detect`");
    // (OpenCV 4.6 decodes with several threads and cannot be asked for one: a message may come one or two
    // reads after the frame it is about, so the frames counted are the right number, not always the right ones)
    cap_.open(path, cv::CAP_FFMPEG);
    watch_ffmpeg_errors();
    if (!cap_.isOpened())
        throw SourceError("video " + path + ": cannot be opened as a video (not a video file, or a codec FFmpeg lacks)");
    fps_ = cap_.get(cv::CAP_PROP_FPS);
    if (!(fps_ > 0 && fps_ < 1000)) fps_ = 30.0;
    frame_count_ = int64_t(cap_.get(cv::CAP_PROP_FRAME_COUNT));
    const long long errors_before = g_ffmpeg_errors.load();
    const bool read_first = cap_.read(bgr_);
    first_concealed_ = g_ffmpeg_errors.load() != errors_before;
    if (!read_first || bgr_.empty())
        throw SourceError("video " + path + ": no frame could be decoded (empty or corrupt file)");
    if (bgr_.cols != size_.width || bgr_.rows != size_.height)
        throw SourceError("video " + path + ": frames are " + std::to_string(bgr_.cols) + "x" +
                          std::to_string(bgr_.rows) + " but camera.width/camera.height say " +
                          std::to_string(size_.width) + "x" + std::to_string(size_.height));
}

ReadStatus VideoFileSource::read(Frame &out) {
    // The constructor already decoded frame 0 into bgr_.
    bool concealed = next_number_ == 0 && first_concealed_;
    if (next_number_ > 0) {
        const long long errors_before = g_ffmpeg_errors.load();
        const bool got = cap_.read(bgr_);
        concealed = g_ffmpeg_errors.load() != errors_before;
        if (!got || bgr_.empty()) {
            // A read that fails before the container's frame count is a damaged or truncated file:
            // skip forward once, then call it the end.
            if (frame_count_ > 0 && next_number_ < frame_count_ - 1 && cap_.grab()) {
                ++next_number_;
                return ReadStatus::DecodeError;
            }
            return ReadStatus::End;
        }
    }
    if (bgr_.cols != size_.width || bgr_.rows != size_.height) {
        ++next_number_;
        return ReadStatus::SizeChanged;
    }
    out.gray = to_gray(bgr_).clone();
    out.events = concealed ? kEventConcealed : 0;
    // Media time from the frame number and the container rate: monotonic even where the container's
    // own timestamps are missing or jump.
    out.t_s = double(next_number_) / fps_;
    out.number = next_number_++;
    return ReadStatus::Ok;
}

} // namespace hw
