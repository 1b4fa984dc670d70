#include "capture/frame_source.hpp"

#include "capture/image_folder_source.hpp"
#include "capture/push_source.hpp"
#include "capture/video_capture_source.hpp"
#include "base/errors.hpp"
#include "base/params.hpp"

#include <opencv2/imgproc.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>

namespace hw {

using nlohmann::json;

cv::Mat to_gray(const cv::Mat &img) {
    if (img.depth() != CV_8U) throw std::invalid_argument("frame must be 8-bit (got OpenCV depth " + std::to_string(img.depth()) + ")");
    cv::Mat gray;
    switch (img.channels()) {
    case 1: return img;
    case 3: cv::cvtColor(img, gray, cv::COLOR_BGR2GRAY); return gray;
    case 4: cv::cvtColor(img, gray, cv::COLOR_BGRA2GRAY); return gray;
    default: throw std::invalid_argument("frame must have 1, 3 or 4 channels, got " + std::to_string(img.channels()));
    }
}

bool is_image_file_name(const std::string &path) {
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
    for (const char *e : {".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff", ".webp"})
        if (ext == e) return true;
    return false;
}

namespace {

template <class T> T get_or(const json &j, const char *key, T fallback) {
    if (!j.contains(key)) return fallback;
    try {
        return j.at(key).get<T>();
    } catch (const json::exception &) {
        throw ConfigError(std::string("source.") + key + ": wrong type (" + j.at(key).dump() + ")");
    }
}

std::unique_ptr<FrameSource> open_camera(const json &j, int api, SourceSize size) {
    CameraSpec s;
    s.api = api;
    if (j.contains("device")) {
        if (j["device"].is_number_integer()) s.index = j["device"].get<int>();
        else if (j["device"].is_string()) s.device = j["device"].get<std::string>();
        else throw ConfigError("source.device: expected a path such as /dev/video0 or an index");
    }
    s.index = get_or(j, "index", s.index);
    s.guid = get_or<std::string>(j, "guid", "");
    s.width = get_or(j, "width", size.width);
    s.height = get_or(j, "height", size.height);
    s.fps = get_or(j, "fps", 30.0);
    s.pixel_format = get_or<std::string>(j, "pixel_format", "");
    if (!s.pixel_format.empty() && s.pixel_format.size() != 4)
        throw ConfigError("source.pixel_format: a V4L2 FOURCC of 4 characters such as YUYV or MJPG");
    if (!s.guid.empty() && s.guid.find_first_not_of("0123456789abcdefABCDEFx") != std::string::npos)
        throw ConfigError("source.guid: expected a hexadecimal GUID such as 0x0814436102a3e5f1");
    auto cam = std::make_unique<CameraSource>(s, size);
    // In the car the service starts before the camera may be ready: with wait_for_device it starts
    // anyway and the loop reconnects (a camera fault until then). Otherwise a missing camera is an error.
    if (!get_or(j, "wait_for_device", false)) cam->open_or_throw();
    return cam;
}

} // namespace

std::unique_ptr<FrameSource> open_source(const std::string &json_text, SourceSize size, int push_capacity) {
    json j;
    try {
        j = json::parse(json_text);
    } catch (const json::parse_error &e) {
        throw ConfigError(std::string("source description is not valid JSON: ") + e.what());
    }
    if (!j.is_object() || !j.contains("kind") || !j["kind"].is_string())
        throw ConfigError("source.kind: missing; one of v4l2, firewire, video, folder, push");
    const std::string kind = j["kind"];
    if (kind == "v4l2") return open_camera(j, cv::CAP_V4L2, size);
    if (kind == "firewire") return open_camera(j, cv::CAP_FIREWIRE, size);
    if (kind == "video") {
        if (!j.contains("path") || !j["path"].is_string()) throw ConfigError("source.path: missing for a video source");
        return std::make_unique<VideoFileSource>(j["path"].get<std::string>(), size);
    }
    if (kind == "folder") {
        if (!j.contains("path") || !j["path"].is_string()) throw ConfigError("source.path: missing for a folder source");
        return std::make_unique<ImageFolderSource>(j["path"].get<std::string>(), get_or(j, "fps", 0.0), size);
    }
    if (kind == "push") return std::make_unique<PushSource>(size, push_capacity);
    throw ConfigError("source.kind: '" + kind + "' is not one of v4l2, firewire, video, folder, push");
}

} // namespace hw
