#include "core/parallax_stage.hpp"

#include "base/stopwatch.hpp"
#include "detect/detector_parallax.hpp"
#include "lanes/lane_tracker.hpp"
#include "road/road_motion_stage.hpp"
#include "track/tracker_particles.hpp"

#include <algorithm>
#include <stdexcept>

namespace hw {

bool is_parallax_stage(const std::string &stage) { return stage == "homography" || stage == "parallax"; }

FrameOutput run_parallax_stage(const std::string &stage, const cv::Mat &stacked, const Config &cfg) {
    if (!is_parallax_stage(stage)) throw std::invalid_argument("not a parallax stage: '" + stage + "'");
    const int W = cfg.camera.width, H = cfg.camera.height;
    if (stacked.type() != CV_8UC1) throw std::invalid_argument("frames must be 8-bit gray (CV_8UC1)");
    if (stacked.cols != W || stacked.rows < 2 * H || stacked.rows % H != 0)
        throw std::invalid_argument("stage '" + stage + "' takes K >= 2 frames of " + std::to_string(W) + "x" +
                                    std::to_string(H) + " stacked vertically, got " + std::to_string(stacked.cols) +
                                    "x" + std::to_string(stacked.rows));
    Stopwatch total;
    LaneTracker lanes(cfg.lanes, cfg.camera);
    const auto &parallax = cfg.get<ParallaxSection>("parallax");
    RoadMotionStage road(cfg.road_features, cfg.homography, parallax, cfg.camera);
    auto *detector = new ParallaxDifferenceDetector(parallax, cfg.camera);
    DetectorSet detectors;
    detectors.parts.emplace_back(detector);
    ParticleTracker tracker(cfg.get<ParticleParams>("particles"), cfg.camera);
    FrameOutput out;
    out.width = W;
    out.height = H;
    std::vector<TrackState> tracks;
    const int K = stacked.rows / H;
    for (int k = 0; k < K; ++k) {
        const cv::Mat frame = stacked.rowRange(k * H, (k + 1) * H);
        out.lanes = LaneModel{};
        lanes.update(frame, out.lanes);
        out.times = StageTimes{};
        const RoadMotionFrame &motion = road.update(frame, k / 30.0, out.lanes, EgoMotion{}, tracks, out.times);
        tracks.clear();
        const FrameContext ctx{frame, k / 30.0, k, out.lanes, cfg.camera, EgoMotion{}, &motion};
        tracker.step(ctx, detectors, tracks, out.times, out.full_detection);
        detector->end_frame(ctx.road());
    }
    const float vp_y = std::isfinite(out.lanes.vanishing_point.y) ? out.lanes.vanishing_point.y
                                                                   : float(cfg.camera.horizon_row());
    out.horizon_row = vp_y;
    out.full_detection = road.homography().status == HomographyKalman::Status::kAccepted;
    std::vector<cv::Rect2f> boxes;
    for (const auto &m : detector->last().measurements) boxes.push_back(m.box);
    const auto res = road.road_residual(out.lanes, boxes);
    out.image_change = res.aligned;
    out.image_mean = res.unaligned;
    out.image_stddev = res.aligned_raw;
    if (stage == "parallax")
        for (const auto &m : detector->last().measurements) {
            TrackState t;
            t.box = m.box;
            t.confidence = std::min(1.f, m.sad / 64.f);
            out.tracks.push_back(t);
        }
    out.total_ms = total.ms();
    out.t_done_s = monotonic_s();
    return out;
}

} // namespace hw
