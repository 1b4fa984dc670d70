#include "track/parallax_stage.hpp"

#include "core/stopwatch.hpp"
#include "lanes/lane_tracker.hpp"
#include "track/parallax_tracker.hpp"

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
    ParallaxTracker tracker(cfg.road_features, cfg.homography, cfg.parallax, cfg.particles, cfg.camera);
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
        tracks.clear();
        FrameContext ctx{frame, k / 30.0, k, out.lanes, cfg.camera};
        tracker.step(ctx, tracks, out.times, out.full_detection);
    }
    const float vp_y = std::isfinite(out.lanes.vanishing_point.y) ? out.lanes.vanishing_point.y
                                                                   : float(cfg.camera.horizon_row());
    out.horizon_row = vp_y;
    out.full_detection = tracker.homography().status == HomographyKalman::Status::kAccepted;
    const auto res = tracker.road_residual(out.lanes);
    out.image_change = res.aligned;
    out.image_mean = res.unaligned;
    out.image_stddev = res.aligned_raw;
    if (stage == "parallax")
        for (const auto &m : tracker.detection().measurements) {
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
