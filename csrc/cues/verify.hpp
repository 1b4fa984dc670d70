// verify.hpp - verification of shadow hypotheses by vertical edges (thesis 2.4.2.2).
//
// For each bottom edge: check the shadow's width against the vehicle expected at its row (too
// narrow: rejected; moderately too wide: a long low-sun shadow whose vehicle is searched inside it);
// take the ROI above the edge, widened by margin_px each side, half the edge length high; project
// its vertical edges onto the columns and take the strongest column left and right of the centre as
// the sides. A vehicle is one bottom edge plus two sides that both stand out against the road, at a
// width that fits the row, standing on smooth road. The top follows from how far up both sides reach, else from a car's
// aspect (vehicle_shape.aspect; the thesis: no consistent cue marks the roof).
#pragma once

#include "cues/hypothesis.hpp"
#include "cues/shadow.hpp"
#include "cues/vehicle_top.hpp"
#include "geometry/vehicle_shape.hpp"

namespace hw {

struct VerifyParams {
    int margin_px = 6;              // px; ROI widened each side of the bottom edge (thesis: 6)
    double margin_frac = 0.3;       // fraction of the edge width, when larger than margin_px
    double roi_height_frac = 0.5;   // ROI height as a fraction of the edge width (thesis: 1/2)
    double shadow_min_ratio = 0.5;  // shadow narrower than this many expected widths: rejected
    double shadow_max_ratio = 1.5;  // wider: a long shadow, the vehicle is searched inside it
    double box_min_ratio = 0.55;    // verified width / expected width, lower bound
    double box_max_ratio = 1.6;     // upper bound (trucks and vans are wider than a car)
    double side_rel = 0.06;         // a side's mean vertical-edge step / road gray level, at least
    double side_min_gray = 3.0;     // gray levels; floor of that step on dark roads
    bool find_top = true;           // top from how far up both sides reach (else always shape.aspect)
    TopSearch top;                  // its thresholds; its bounds are the vehicle's (share)
    VehicleShapeParams shape;       // section "vehicle_shape" (aspect when no top is found, top bounds), taken by share
    double road_texture_max = 0.25; // texture of the strip under the bottom edge / its gray level, at most
    double nms_iou = 0.3;           // overlapping detections: the weaker is dropped

    void share(const SectionLookup &c) {
        shape = c.get<VehicleShapeParams>("vehicle_shape");
        top.min_aspect = shape.top_min_aspect;
        top.max_aspect = shape.max_aspect;
    }
    void bind(ParamMap &m) {
        m.add("margin_px", margin_px, 0, 100,
              "px; the ROI is the bottom edge widened by this each side (thesis: 6 px at 640x480)");
        m.add("margin_frac", margin_frac, 0.0, 1.0,
              "fraction of the edge width; margin used instead of margin_px when larger, so near "
              "vehicles and high-resolution images still get their sides inside the ROI");
        m.add("roi_height_frac", roi_height_frac, 0.1, 2.0,
              "fraction of the edge width; height of the ROI above the bottom edge in which vertical "
              "edges are projected (thesis: half the shadow length)");
        m.add("shadow_min_ratio", shadow_min_ratio, 0.0, 2.0,
              "expected vehicle widths; a shadow narrower than this is not under a vehicle of this row");
        m.add("shadow_max_ratio", shadow_max_ratio, 0.5, 10.0,
              "expected vehicle widths; a shadow wider than this is a long shadow (low sun): the "
              "vehicle's two sides are searched inside it at the expected spacing instead of at its ends");
        m.add("box_min_ratio", box_min_ratio, 0.1, 2.0,
              "expected vehicle widths; narrowest verified box (the distance between the two sides)");
        m.add("box_max_ratio", box_max_ratio, 0.5, 5.0,
              "expected vehicle widths; widest verified box; 1.6 admits trucks at 1.8 m nominal width");
        m.add("side_rel", side_rel, 0.0, 1.0,
              "fraction of the road gray level; each side's mean vertical-edge step over the ROI height "
              "must reach this, else the candidate lacks two sides and is rejected");
        m.add("side_min_gray", side_min_gray, 0.0, 100.0, "gray levels; floor of the side threshold");
        m.add("find_top", find_top,
              "find the top as the row up to which both side edges reach (vans and trucks are taller "
              "than a car's aspect says) between vehicle_shape.top_min_aspect and max_aspect widths; false: "
              "always vehicle_shape.aspect");
        m.add("top_keep_frac", top.keep_frac, 0.05, 1.0,
              "fraction of the side edges' strength on the lower body that still counts as a side "
              "going up; lower follows faint upper sides further, higher stops at the first weak row");
        m.add("top_max_gap", top.max_gap, 0, 50, "rows; gaps in the side edges bridged going up (seams)");
        m.add("road_texture_max", road_texture_max, 0.0, 10.0,
              "mean gradient magnitude / gray level of the strip under the bottom edge, at most: a vehicle's shadow "
              "lies on smooth asphalt, guardrails' and verges' on texture (docs/detection.md)");
        m.add("nms_iou", nms_iou, 0.0, 1.0,
              "IoU; of two overlapping detections the lower-scoring one is dropped");
    }
};

struct Detection {
    cv::Rect2f box;
    float score = 0.f;  // 0..1
    bool top_measured = true;  // false: no top cue, the height is the fixed aspect's guess (shape.aspect x width)
};

// A verified detection as a detector part's hypothesis (its score also its strength; whether its top was measured).
inline Hypothesis hypothesis_of(const Detection &d, const char *source) {
    Hypothesis h = hypothesis_of(d.box, d.score, d.score, source);
    h.top_measured = d.top_measured;
    return h;
}

// Verifies hypotheses; detections are returned strongest first, overlaps suppressed.
std::vector<Detection> verify_hypotheses(const cv::Mat &gray, const std::vector<ShadowHypothesis> &hyps,
                                         const LaneModel &lanes, const CameraParams &cam,
                                         const VerifyParams &p);

// Verifies one hypothesis (a bottom edge at h.box's bottom row from h.box.x over h.box.width, the vehicle
// width expected there, the road's gray level): false if it is not a vehicle, else its box and score.
// The one verification of every detector's hypotheses (detect/merge_hypotheses.hpp merges them first).
bool verify_one(const cv::Mat &gray, const ShadowHypothesis &h, const VerifyParams &p, Detection &out);

// Indices of the detections kept, strongest first: each is dropped that overlaps a kept stronger one by
// more than nms_iou.
std::vector<size_t> strongest_apart(const std::vector<Detection> &found, double nms_iou);

// Side threshold of the verification for a road of gray level road_gray (mean step, gray levels).
float side_threshold(float road_gray, const VerifyParams &p);

} // namespace hw
