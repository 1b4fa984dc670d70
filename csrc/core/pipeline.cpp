#include "core/pipeline.hpp"

#include "base/stopwatch.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

namespace {

std::vector<DetectedBox> boxes_of(const std::vector<Hypothesis> &hyps) {
    std::vector<DetectedBox> out;
    for (const auto &h : hyps) out.push_back({h.box, h.score});
    return out;
}

} // namespace

Pipeline::Pipeline(const Config &cfg)
    : cfg_(cfg), lanes_(cfg.lanes, cfg.camera), parts_(make_parts(cfg)), calib_(cfg.self_calibration, cfg.camera),
      horizon_(cfg.horizon, cfg.camera),
      kinematics_(cfg.kinematics, cfg.camera), lead_(cfg.lead, cfg.camera) {
    set_lane_search();
}

void Pipeline::set_lane_search() {
    if (!cfg_.self_calibration.enabled || !cfg_.self_calibration.from_scratch) return;
    CameraParams cam = calib_.camera();
    const double tol = cfg_.lanes.assembly.horizon_tolerance_deg;
    const auto [centre, half_width] = calib_.search_window();
    if (calib_.searching() && half_width > tol) {
        cam.pitch_deg = centre;
        lanes_.set_search_window(cam, half_width);
    } else {
        lanes_.set_search_window(cam, tol);
    }
}

void Pipeline::check_frame(const cv::Mat &gray) const {
    if (gray.type() != CV_8UC1) throw std::invalid_argument("frame must be 8-bit gray (CV_8UC1)");
    if (gray.cols != cfg_.camera.width || gray.rows != cfg_.camera.height)
        throw std::invalid_argument("frame is " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows) +
                                    " but camera.width/camera.height say " + std::to_string(cfg_.camera.width) +
                                    "x" + std::to_string(cfg_.camera.height));
}

FrameOutput Pipeline::process(const Frame &frame) {
    check_frame(frame.gray);
    if (frame.t_s < last_t_s_)
        throw std::invalid_argument("frame timestamp " + std::to_string(frame.t_s) + " s goes backwards (previous " +
                                    std::to_string(last_t_s_) + " s)");
    last_t_s_ = frame.t_s;

    Stopwatch total;
    FrameOutput out;
    out.frame_number = frame.number;
    out.t_capture_s = frame.t_s;
    out.width = frame.gray.cols;
    out.height = frame.gray.rows;
    out.events = frame.events;

    const ImageStats stats = image_stats_.measure(frame.gray);
    out.image_mean = stats.mean;
    out.image_stddev = stats.stddev;
    out.image_change = stats.change;
    {
        Stopwatch sw;
        const bool first = !std::isfinite(prev_t_s_);
        lanes_.update(frame.gray, out.lanes, last_tracks_);
        // Nothing tracked yet: the first frame is a single image, and gets the single image's lane model, so that
        // its detections are exactly what `headway detect` finds in it (detect_image). Not when the camera's
        // mounting is yet to be found (self_calibration.from_scratch): the lane tracker's wide search is needed.
        if (first && !cfg_.self_calibration.from_scratch) out.lanes = detect_lanes(frame.gray, cfg_.lanes, cfg_.camera);
        out.times.add("lanes", sw.ms());
    }
    if (parts_.tracker) {
        const EgoMotion ego{ego_speed_mps_, ego_yaw_rate_rps_};
        const RoadMotionFrame *motion = nullptr;
        if (parts_.road) {
            motion = &parts_.road->update(frame.gray, frame.t_s, out.lanes, ego, last_tracks_, out.times);
            out.road = motion->motion;
        }
        // from scratch, the camera as self-calibration has it (the previous frame's estimate): the mounting found
        // places the detectors' road prior too
        const CameraParams cam = cfg_.self_calibration.from_scratch ? calib_.camera() : cfg_.camera;
        const FrameContext ctx{frame.gray, frame.t_s, frame.number, out.lanes, cam, ego, motion};
        parts_.detectors.last.clear();
        parts_.detectors.last_frame = frame.number;
        parts_.tracker->step(ctx, parts_.detectors, out.tracks, out.times, out.full_detection);
        if (out.full_detection) {
            out.detections = boxes_of(parts_.detectors.last);
            out.detections_frame = parts_.detectors.last_frame;
        }
        for (auto &d : parts_.detectors.parts) d->end_frame(ctx.road());
        if (parts_.road && cfg_.homography.measure_residual) {
            // the road without this frame's detections (found on this frame: the parallax part runs on it)
            std::vector<cv::Rect2f> boxes;
            if (parts_.detectors.last_frame == frame.number)
                for (const auto &h : parts_.detectors.last) boxes.push_back(h.box);
            const auto res = parts_.road->road_residual(out.lanes, boxes);
            out.road.residual = res.aligned;
            out.road.residual_unaligned = res.unaligned;
            out.road.residual_raw = res.aligned_raw;
        }
        last_tracks_ = out.tracks;
    }
    // the car's own motion: yaw rate from CAN, else from the road plane's image motion (parallax preset), with
    // the mounting the road-motion stage fitted it around (self-calibration's estimate before this frame)
    EgoMotion ego{ego_speed_mps_, ego_yaw_rate_rps_};
    if (!std::isfinite(ego.yaw_rate_rps) && out.road.state == RoadMotion::State::kAccepted)
        ego.yaw_rate_rps = yaw_rate_of_road_motion(out.road.H, calib_.camera(), frame.t_s - prev_t_s_);
    prev_t_s_ = frame.t_s;
    {
        Stopwatch sw;
        // The curve gate takes the road motion's yaw rate only once pitch and yaw have converged: fitted around a
        // mounting still being found (a yaw degrees off), it reads part of the travel as a turn and would shut the
        // gate for the yaw's first measurements (on 6 of the 12 real lane clips, no yaw measurement in 20 frames).
        const bool bus_yaw_rate = std::isfinite(ego_yaw_rate_rps_);
        calib_.update(out.lanes, ego.speed_mps, bus_yaw_rate || !calib_.searching() ? ego.yaw_rate_rps : NAN, frame.t_s,
                      out.road);
        const CalibrationEstimate e = calib_.estimate();
        if (e.active) {
            const CameraParams cam = calib_.camera();
            horizon_.set_camera(cam);
            kinematics_.set_camera(cam);
            lead_.set_camera(cam);
            if (parts_.road) parts_.road->set_camera(cam);
            if (parts_.tracker) parts_.tracker->set_camera(cam);
            set_lane_search();
        }
        out.calib_active = e.active;
        out.calib_pitch_deg = float(e.pitch_deg);
        out.calib_yaw_deg = float(e.yaw_deg);
        out.calib_height_m = float(e.height_m);
        out.calib_pitch_sigma_deg = float(e.pitch_sigma_deg);
        out.calib_yaw_sigma_deg = float(e.yaw_sigma_deg);
        out.calib_height_sigma_m = float(e.height_sigma_m);
        out.calib_updates = e.updates;
        out.calib_state = int(e.state);
        out.times.add("calibration", sw.ms());
    }
    {
        Stopwatch sw;
        out.horizon_row = float(horizon_.update(out.lanes));
        kinematics_.update(out.tracks, out.horizon_row, frame.t_s);
        out.times.add("geometry", sw.ms());
    }
    {
        Stopwatch sw;
        out.lead_id = lead_.update(out.tracks, out.lanes, ego, out.horizon_row);
        out.times.add("lead", sw.ms());
    }
    out.total_ms = total.ms();
    out.t_done_s = monotonic_s();
    return out;
}

ImageDetections Pipeline::detect_image(const std::string &detector, const cv::Mat &gray) {
    check_frame(gray);
    DetectorSet *set = &parts_.detectors;
    if (!detector.empty()) {
        auto it = single_parts_.find(detector);
        if (it == single_parts_.end()) {
            DetectorSet named;
            try {
                named.parts.push_back(make_detector(detector, cfg_));
            } catch (const ConfigError &e) {
                throw std::invalid_argument(std::string("detector: ") + e.what());
            }
            named.fuse = cfg_.fuse;
            it = single_parts_.emplace(detector, std::move(named)).first;
        }
        set = &it->second;
    } else if (set->parts.empty()) {
        throw std::invalid_argument("this composition has no detector parts (pipeline.detectors): name one of " +
                                    std::string(detector_choices()));
    }
    for (const auto &d : set->parts)
        if (d->needs_road_motion())
            throw std::invalid_argument("one image alone: detector parts that need the road's motion (parallax) need "
                                        "two frames and run in process()");
    Stopwatch total;
    ImageDetections out;
    Stopwatch sw;
    const LaneModel lanes = detect_lanes(gray, cfg_.lanes, cfg_.camera);
    out.times.add("lanes", sw.ms());
    const RoadContext ctx{gray, 0.0, lanes, cfg_.camera, nullptr, true};
    std::vector<Hypothesis> hyps;
    set->detect(ctx, hyps, out.times);
    out.boxes = boxes_of(hyps);
    out.horizon_row = float(cfg_.camera.horizon_row());
    out.total_ms = total.ms();
    return out;
}

void Pipeline::reset() {
    lanes_.reset();
    if (parts_.tracker) {
        parts_.tracker->reset();
        parts_.tracker->set_camera(cfg_.camera);
    }
    parts_.detectors.reset();
    for (auto &[name, set] : single_parts_) set.reset();
    if (parts_.road) {
        parts_.road->reset();
        parts_.road->set_camera(cfg_.camera);
    }
    last_tracks_.clear();
    image_stats_.reset();
    calib_.reset();
    set_lane_search();
    horizon_.set_camera(cfg_.camera);
    horizon_.reset();
    kinematics_.set_camera(cfg_.camera);
    lead_.set_camera(cfg_.camera);
    prev_t_s_ = NAN;
    kinematics_.reset();
    lead_.reset();
    last_t_s_ = -1e300;
}

} // namespace hw
