#include "core/pipeline.hpp"

#include "core/stopwatch.hpp"
#include "detect/shadow.hpp"
#include "detect/verify.hpp"
#include "track/parallax_stage.hpp"
#include "track/parallax_tracker.hpp"
#include "track/phd_tracker.hpp"
#include "track/thesis_tracker.hpp"

#include <stdexcept>

namespace hw {

namespace {

std::unique_ptr<VehicleTracker> make_tracker(const Config &c) {
    if (c.pipeline.preset == "thesis") return std::make_unique<ThesisTracker>(c.shadow, c.verify, c.kalman);
    if (c.pipeline.preset == "parallax")
        return std::make_unique<ParallaxTracker>(c.road_features, c.homography, c.parallax, c.particles, c.camera);
    if (c.pipeline.preset == "phd")
        return std::make_unique<PhdTracker>(c.shadow, c.verify, c.horizon, c.phd, c.camera);
    if (c.pipeline.preset == "none") return nullptr;
    throw ConfigError("pipeline.preset: unknown preset '" + c.pipeline.preset + "'");
}

} // namespace

Pipeline::Pipeline(const Config &cfg)
    : cfg_(cfg), lanes_(cfg.lanes, cfg.camera), tracker_(make_tracker(cfg)), horizon_(cfg.horizon, cfg.camera),
      kinematics_(cfg.kinematics, cfg.camera), lead_(cfg.lead, cfg.camera) {}

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
        lanes_.update(frame.gray, out.lanes);
        out.times.add("lanes", sw.ms());
    }
    if (tracker_) {
        FrameContext ctx{frame.gray, frame.t_s, frame.number, out.lanes, cfg_.camera,
                         EgoMotion{ego_speed_mps_, ego_yaw_rate_rps_}};
        tracker_->step(ctx, out.tracks, out.times, out.full_detection);
        out.road = tracker_->road_motion();
    }
    {
        Stopwatch sw;
        out.horizon_row = float(horizon_.update(out.lanes));
        kinematics_.update(out.tracks, out.horizon_row, frame.t_s);
        out.times.add("geometry", sw.ms());
    }
    {
        Stopwatch sw;
        out.lead_id = lead_.update(out.tracks, out.lanes, EgoMotion{ego_speed_mps_, ego_yaw_rate_rps_});
        out.times.add("lead", sw.ms());
    }
    out.total_ms = total.ms();
    out.t_done_s = monotonic_s();
    return out;
}

FrameOutput Pipeline::run_stage(const std::string &stage, const cv::Mat &gray) {
    // Two-frame units (frames stacked vertically): see track/parallax_stage.hpp.
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
    if (stage != "lanes") {
        Stopwatch sw;
        const auto hyps = shadow_hypotheses(gray, out.lanes, cfg_.camera, cfg_.shadow);
        out.times.add("hypotheses", sw.ms());
        if (stage == "hypotheses") {
            for (const auto &h : hyps) {
                TrackState t;
                t.box = h.box;
                t.confidence = h.strength;
                out.tracks.push_back(t);
            }
        } else {
            Stopwatch sv;
            const auto dets = verify_hypotheses(gray, hyps, out.lanes, cfg_.camera, cfg_.verify);
            out.times.add("verify", sv.ms());
            for (const auto &d : dets) {
                TrackState t;
                t.box = d.box;
                t.confidence = d.score;
                out.tracks.push_back(t);
            }
        }
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
    if (tracker_) tracker_->reset();
    image_stats_.reset();
    horizon_.reset();
    kinematics_.reset();
    lead_.reset();
    last_t_s_ = -1e300;
}

} // namespace hw
