// proposals/part.hpp - detector part "proposals": the learned first stage (docs/detection.md).
//
// A small convolutional network run once on the reduced image (proposal_net.hpp) gives the vehicles' centres as
// peaks of an objectness map, each with its box. The top_k strongest peaks whose box stands below the horizon are
// judged by the CNN verifier (vehicle_verifier_cnn.hpp, the cascade's) in one batch, and with refine_boxes its box
// output moves each onto the vehicle. Each box (the moved one; the peak's own without refine_boxes or a verifier,
// checked then before the verifier) is then checked against the flat road like every other hypothesis: the vehicle
// height it implies (h_cam h / (y_b - y_h)) within [min_vehicle_height_m, max_vehicle_height_m], and its width against
// the vehicle width expected at its bottom row (road_prior.hpp: lane model, else the camera) within [min_width_ratio,
// max_width_ratio] (a box cut by the image's left or right border is not held to the lower bound). A candidate
// overlapping a more confident one at IoU >= nms_iou is dropped.
// Each output: box cut to the image, foot = bottom centre, score = the verifier's probability (the peak's heat without
// a verifier), appearance = that same learned score, strength = the peak's heat, source "proposals".
// Stage times: "proposals" (resize, network, decoding, geometry) and "prop_verifier" (the ABI keeps 15 characters of a
// stage name).
#pragma once

#include "base/params.hpp"
#include "base/sections.hpp"
#include "detect/detector.hpp"
#include "detect/proposals/proposal_net.hpp"
#include "geometry/road_params.hpp"
#include "geometry/vehicle_shape.hpp"

#include <memory>
#include <string>

namespace hw {

class VehicleVerifier;

struct ProposalsParams {
    std::string model;              // path of the proposal network (ONNX); "" = the shipped model (filled in by Python)
    std::string verifier;           // path of the verifier; "" = the shipped CNN verifier (Python), "off" = none
    RoadParams road;                // section "road" (lane widths), taken by share
    VehicleShapeParams shape;       // section "vehicle_shape" (the vehicle width), taken by share
    int input_width = 320;          // px of the network's input
    double min_heat = 0.05;         // peaks below are not candidates
    int top_k = 24;                 // strongest candidates verified (and output)
    int verifier_windows = 8;       // the window count handed to the verifier's log(1 + n) feature
    bool verify_mirrored = true;    // the verifier also judges each believed crop's mirror image (mean of the two)
    bool refine_boxes = true;       // a verifier with a box output moves each candidate's box onto the vehicle
    int refine_looks = 4;           // looks of the verifier at each candidate, each moving it again (min of the p)
    // A gate on the height the candidate's box implies, with its own bounds (0.7 / 5.0 m), not the vehicle's size
    // prior (vehicle_shape.max_height_m), so the keys stay here.
    double min_vehicle_height_m = 0.7, max_vehicle_height_m = 5.0;
    double min_width_ratio = 0.35, max_width_ratio = 3.0;
    double nms_iou = 0.5;

    void share(const SectionLookup &c) {  // the lane widths and the vehicle width
        road = c.get<RoadParams>("road");
        shape = c.get<VehicleShapeParams>("vehicle_shape");
    }
    void bind(ParamMap &m) {
        m.add("model", model, nullptr,
              "path of the proposal network (ONNX, `headway train proposals --out X.onnx`); empty = the model shipped "
              "with Headway (app/models/vehicle_proposals.onnx, recipe in docs/detection.md)");
        m.add("verifier", verifier, nullptr,
              "path of the CNN verifier judging the candidates (as cascade.verifier: `headway train verifier --out "
              "X.onnx`); empty = the shipped app/models/vehicle_verifier.onnx; off = none (score = the peak's heat)");
        m.add("input_width", input_width, 64, 1280,
              "px; the image is reduced to this width (aspect kept) for the network; the shipped model was trained at "
              "320 on 1280x720 images");
        m.add("min_heat", min_heat, 0.0, 1.0, "objectness; peaks of the heat map below this are not candidates");
        m.add("top_k", top_k, 1, 200, "candidates; the strongest peaks standing below the horizon (and passing the road checks when no verifier moves them), verified");
        m.add("verifier_windows", verifier_windows, 1, 200,
              "windows; the verifier was trained on the cascade's groups and reads log(1 + n) of their raw windows: "
              "a candidate is handed this n");
        m.add("verify_mirrored", verify_mirrored,
              "true = the verifier also judges the mirror image of each crop it gives at least 0.5 and averages the two "
              "(as cascade.verify_mirrored)");
        m.add("refine_boxes", refine_boxes,
              "true = a verifier with a box output (the shipped one) moves each candidate's box onto the vehicle as that "
              "output says (as cascade.refine_boxes), before the suppression; false = the network's own boxes");
        m.add("refine_looks", refine_looks, 1, 5,
              "looks; with refine_boxes the verifier judges each candidate again where its last look moved it, this many "
              "times in all, and the candidate keeps the lowest of its probabilities (as cascade.rejudge_refined)");
        m.add("min_vehicle_height_m", min_vehicle_height_m, 0.1, 5.0,
              "m; a candidate whose box implies a lower vehicle on a flat road is dropped");
        m.add("max_vehicle_height_m", max_vehicle_height_m, 0.5, 20.0,
              "m; a candidate whose box implies a higher vehicle on a flat road is dropped");
        m.add("min_width_ratio", min_width_ratio, 0.0, 10.0,
              "share of the vehicle width expected at the box's bottom row; narrower candidates are dropped (unless "
              "cut by the image's side)");
        m.add("max_width_ratio", max_width_ratio, 0.1, 100.0,
              "share of the vehicle width expected at the box's bottom row; wider candidates are dropped");
        m.add("nms_iou", nms_iou, 0.05, 1.0,
              "IoU; a candidate overlapping a more confident one at least this much is dropped (1 = keep all)");
    }
};

class ProposalsDetector final : public Detector {
public:
    explicit ProposalsDetector(const ProposalsParams &p);
    ~ProposalsDetector() override;
    bool detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) override;

private:
    ProposalsParams p_;
    ProposalNet net_;
    std::unique_ptr<VehicleVerifier> verifier_;  // null: verifier "off"
};

} // namespace hw
