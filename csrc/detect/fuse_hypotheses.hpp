// fuse_hypotheses.hpp - one list of vehicles from the detector parts of a composition.
//
// The learned detectors (a hypothesis with a finite appearance score: the cascade with its CNN verifier) are
// the primary source of vehicles. The other parts are cues (the shadow detector's verified bottom edges, the
// parallax regions): they add the vehicles the learned detectors missed and raise the score of those they
// confirm, and never remove one.
//   - A learned hypothesis and a cue overlapping at IoU >= match_iou are one vehicle (each learned hypothesis,
//     strongest first, takes its best-overlapping cue not yet taken): the box is the learned one (trained on
//     whole-vehicle boxes, as the annotations draw them), with its bottom edge moved onto a matched shadow edge
//     when shadow_bottom is set; the score min(1, max(c, t) + agree_bonus).
//   - A learned box lower than small_box_px (0 = off, the default: docs/decisions.md) comes from the cascade's
//     smallest windows (20 px high), larger than a far car: a shadow cue it holds (>= 90 % of the cue's area
//     inside; the matched one, else the largest one not taken) confirms it and gives it its box, which the
//     shadow's edges measure to the pixel.
//   - A learned hypothesis no cue confirms keeps its score c.
//   - Two learned parts' hypotheses on one vehicle (IoU >= match_iou) are one: the stronger one, with the
//     agreement bonus.
//   - A cue no learned hypothesis explains keeps cue_weight * t (the shadow detector alone reaches about 0.7
//     precision on real images, the learned detector more); cues of two parts on one vehicle (IoU >= match_iou)
//     are one vehicle, the first part's box with the agreement bonus.
// Returned strongest first (ties in the parts' order). With one detector part, its own hypotheses as they are.
//
// DetectorSet, the composition's detectors asked together, is the detection stage: of a tracked pipeline (the
// tracker asks it for a full detection) and of `headway detect` on one image (Pipeline::detect_image).
#pragma once

#include "base/params.hpp"
#include "cues/detection_stage.hpp"
#include "detect/detection_worker.hpp"
#include "detect/detector.hpp"

#include <memory>
#include <vector>

namespace hw {

struct FuseParams {
    double match_iou = 0.5;      // IoU; a learned hypothesis and a cue overlapping this much are one vehicle
    double agree_bonus = 0.3;    // score added when a cue confirms a vehicle
    double cue_weight = 0.5;     // share of its score a vehicle only a cue finds keeps
    bool shadow_bottom = false;  // a learned box confirmed by a shadow edge takes the shadow's bottom row
    double small_box_px = 0.0;   // px; a learned box lower than this takes the box of a shadow cue it holds

    void bind(ParamMap &m) {
        m.add("match_iou", match_iou, 0.05, 0.95,
              "IoU; a learned detection and a cue (shadow edge, parallax region) overlapping this much are one vehicle");
        m.add("agree_bonus", agree_bonus, 0.0, 1.0, "score added to a vehicle that a cue confirms");
        m.add("cue_weight", cue_weight, 0.0, 1.0,
              "share of its score kept by a vehicle that only a cue (shadow or parallax detector) finds");
        m.add("shadow_bottom", shadow_bottom,
              "a learned box confirmed by a shadow edge takes the shadow's bottom row (where the tyres meet the road)");
        m.add("small_box_px", small_box_px, 0.0, 200.0,
              "px; a learned box lower than this that holds a shadow cue takes the cue's box (a far car is smaller "
              "than the cascade's smallest window, 20 px high; the shadow's edges measure it); 0 = never");
    }
};

// The vehicles of `found`: every part's hypotheses, in the order of pipeline.detectors.
std::vector<Hypothesis> fuse_hypotheses(const std::vector<Hypothesis> &found, const FuseParams &p);

// The composition's detectors, asked together, on the calling thread (detect) or on a worker thread (start, then
// finish some frames later: detect/detection_worker.hpp); the detection stage a tracker asks.
struct DetectorSet final : DetectionStage {
    std::vector<std::unique_ptr<Detector>> parts;
    FuseParams fuse;  // how two or more parts' hypotheses become one list
    std::vector<Hypothesis> last;  // what the last detect() or finish() gave (the pipeline reports it with the frame)
    int64_t last_frame = -1;       // the frame `last` was found on (the pipeline sets it to the frame for detect())

    // The vehicles: one part's hypotheses as they are, several parts' fused; false if no part could run.
    bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;
    // Whether start() can run this composition: no part needs the road's motion (the parallax detector keeps the
    // previous frame's road band in end_frame, every frame, on the frame thread).
    bool can_start() const override;
    // detect() on the worker thread, on copies of the frame, its lane model and the camera.
    void start(const RoadContext &ctx, int64_t frame_number) override;
    // Waits for the detection start() began and gives its vehicles as detect() does (also into last, last_frame),
    // its parts' stage times as "bg_<stage>", its wall time "bg_detect", its CPU time "bg_detect_cpu" and the wait "detect_wait".
    bool finish(std::vector<Hypothesis> &out, StageTimes &times) override;
    // Waits for a detection start() began; its result stays for finish(). (reset(): and drops it.)
    void settle();
    void reset();

private:
    bool find(const RoadContext &ctx, std::vector<Hypothesis> &found, StageTimes &times);
    struct Started {  // what start() handed the worker, and what it found
        cv::Mat gray;
        LaneModel lanes;
        CameraParams camera;
        double t_s = 0.0;
        int64_t frame = -1;
        bool ran = false;
        std::vector<Hypothesis> found;
        StageTimes times;
        float ms = 0.f, cpu_ms = 0.f;
    };
    Started started_;
    bool has_started_ = false;
    std::unique_ptr<DetectionWorker> worker_;  // last: destroyed (joined) before what its job reads
};

} // namespace hw
