#include "core/pipeline.hpp"

#include "base/stopwatch.hpp"
#include "core/parallax_stage.hpp"
#include "detect/shadow.hpp"

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
        // its detections are exactly what `headway detect` finds in it (run_stage "detect"). Not when the camera's
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

FrameOutput Pipeline::run_stage(const std::string &stage, const cv::Mat &gray) {
    // Two-frame units (frames stacked vertically): see core/parallax_stage.hpp.
    if (is_parallax_stage(stage)) return run_parallax_stage(stage, gray, cfg_);
    check_frame(gray);
    Stopwatch total;
    FrameOutput out;
    out.width = gray.cols;
    out.height = gray.rows;
    if (stage != "lanes" && stage != "hypotheses" && stage != "detect")
        throw std::invalid_argument("unknown stage '" + stage + "': one of lanes, hypotheses, detect, homography, parallax");
    {
        Stopwatch sw;
        out.lanes = detect_lanes(gray, cfg_.lanes, cfg_.camera);
        out.times.add("lanes", sw.ms());
    }
    out.horizon_row = float(cfg_.camera.horizon_row());
    if (stage == "hypotheses") {
        Stopwatch sw;
        for (const auto &h : shadow_hypotheses(gray, out.lanes, cfg_.camera, cfg_.get<ShadowParams>("shadow"))) {
            TrackState t;
            t.box = h.box;
            t.confidence = h.strength;
            out.tracks.push_back(t);
        }
        out.times.add("hypotheses", sw.ms());
    } else if (stage == "detect") {
        // The pipeline's detection stage on one image: the composition's detectors (those that work on one
        // image), fused as in a tracked pipeline (DetectorSet, detect/fuse_hypotheses.hpp).
        for (const auto &d : parts_.detectors.parts)
            if (d->needs_road_motion())
                throw std::invalid_argument("stage 'detect' runs on one image, and detector parts that need the road's "
                                            "motion (parallax) need two frames: stage 'parallax'");
        if (parts_.detectors.parts.empty())
            throw std::invalid_argument("stage 'detect' runs the detectors of pipeline.detectors, and this composition "
                                        "has none");
        std::vector<Hypothesis> hyps;
        const RoadContext ctx{gray, 0.0, out.lanes, cfg_.camera, nullptr, true};
        parts_.detectors.detect(ctx, hyps, out.times);
        out.detections = boxes_of(hyps);
        for (const auto &h : hyps) {
            TrackState t;
            t.box = h.box;
            t.confidence = h.score;
            out.tracks.push_back(t);
        }
    }
    if (stage != "lanes") {
        out.full_detection = true;
        // single-image range from the calibrated horizon (no history: no range rate or TTC)
        TrackKinematics(cfg_.kinematics, cfg_.camera).update(out.tracks, out.horizon_row, 0.0);
    }
    out.total_ms = total.ms();
    out.t_done_s = monotonic_s();
    return out;
}

void Pipeline::reset() {
    lanes_.reset();
    if (parts_.tracker) {
        parts_.tracker->reset();
        parts_.tracker->set_camera(cfg_.camera);
    }
    parts_.detectors.reset();
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
