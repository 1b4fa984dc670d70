// cascade/cascade_scan.hpp - vehicles by the project's boosted Haar cascade (paper 004, docs/detection.md).
//
// The shipped OpenCV cascade XML (trained by `headway train cascade`) is run by HaarCascade
// (haar_cascade.hpp: OpenCV's evaluation and scan, window for window, faster) only where a vehicle can stand. The
// cascade's window W x H (the XML's own, any size and aspect; 30 x 20 shipped) was trained on windows of the
// annotated box's height, so a window of height h_s is a vehicle whose box is h_s pixels high. On a
// flat road a vehicle of height H_v (m) whose bottom is at row y_b has
//     h_s = H_v * (y_b - y_h) / h_cam        (pinhole: h_s = fy H_v / Z, Z = fy h_cam / (y_b - y_h))
// so each window size is scanned only in the band of rows where its bottom row lies in
//     [y_h + h_s h_cam / H_max, y_h + h_s h_cam / H_min]   (H_min: a low car, H_max: a truck),
// and only across the road area (lane model widened to `adjacent_lanes` each side, or the camera
// fallback) plus half a window each side. Every window size is scanned on the band resized by
// 1/scale (a near car filling a third of the image is a small image to scan); window sizes grow by
// `scale_factor` from the model's own up to `max_window_frac` of the image height.
// Raw windows accepted by every stage are grouped (IoU >= group_iou with the group's strongest
// window, box = mean of the group); a group of n windows gets confidence n / (n + neighbors_half),
// and groups of fewer than min_neighbors windows are dropped; only the first max_groups groups (strongest
// seed window first) are kept, which bounds the verifier's cost. With a verifier (vehicle_verifier.hpp: a
// small CNN on the box's crop, or the HOG of the box, with log(1 + n) and the vehicle height the box
// implies, through a trained network) the confidence is instead its probability that the group's box
// holds a vehicle (all the groups of a frame judged at once), and a CNN verifier with a box output moves each
// group's box onto the vehicle (refine_boxes; vehicle_verifier_cnn.hpp). Last, a detection
// overlapping a more confident one at IoU >= nms_iou is dropped (two groups on one vehicle).
#pragma once

#include "base/params.hpp"
#include "base/types.hpp"
#include "cues/road_prior.hpp"
#include "geometry/camera.hpp"

#include <opencv2/core.hpp>

#include <memory>
#include <string>
#include <vector>

namespace cv { class CascadeClassifier; }

namespace hw {

struct CascadeParams {
    std::string model;                  // path of the cascade XML; "" = the shipped model (filled in by Python)
    std::string verifier;               // path of the verifier model; "" = the shipped one (Python), "off" = none
    RoadPriorParams road;               // scan area (keys in this section); the vehicle's size (vehicle_shape)
    // m; lowest vehicle box (a low car, partly hidden); the tallest is vehicle_shape.max_height_m. Only the cascade
    // bounds the height from below (the proposals' gate has its own, looser bounds), so the key stays here.
    double min_vehicle_height_m = 1.0;
    double scale_factor = 1.12;         // ratio of successive window sizes
    double max_window_frac = 0.6;       // largest window height as a fraction of the image height
    double min_window_px = 0.0;         // px; smaller window sizes are not scanned (0: from the model's own)
    int step_px = 2;                    // px in the resized band between windows (OpenCV's own step is 2)
    int threads = 2;                    // threads the scan's sizes and the verifier's crops are shared among; 1 = caller
                                        // (base/worker_pool.hpp)
    bool opencv_scan = false;           // scan with cv::CascadeClassifier (the reference) instead of HaarCascade
    bool verifier_dnn = false;          // the CNN verifiers run by cv::dnn (the reference) instead of their own forward pass
    int scan_lanes = 0;                 // windows HaarCascade evaluates at once: 0 = the widest the CPU has, 4, 8
    double group_iou = 0.45;            // raw windows overlapping the group's strongest this much join it
    int min_neighbors = 2;              // groups of fewer raw windows are dropped
    double neighbors_half = 6.0;        // a group of this many windows gets confidence 0.5
    int verify_min_neighbors = 0;       // groups of fewer raw windows skip the verifier (confidence from n)
    int max_groups = 0;                 // only the groups with the strongest seed windows are kept (0 = all)
    bool refine_boxes = true;           // a verifier with a box output moves each box before the suppression
    bool rejudge_refined = true;        // a moved box is judged again where it now stands (min of the two)
    double rejudge_min_p = 0.5;         // only boxes the first look gives at least this are judged again
    double rejudge_move = 0.5;          // the second look moves the box again by this share of its offsets
    bool lazy_rejudge = true;           // no second look at a box a more confident one judged twice will suppress
    bool verify_mirrored = true;        // the verifier also judges each crop's mirror image (mean of the two)
    double mirror_min_p = 0.5;          // ... of the crops it gives at least this
    double nms_iou = 0.3;               // a detection overlapping a more confident one this much is dropped (1 = none)
    double border_frac = 0.5;           // share of a window's width that may lie beyond the left or right border
    int tracked_slices = 1;             // tracked: the scan spread over this many full detections, a block of sizes each
    double tracked_far_m = 0.0;         // tracked slices: a car's sizes beyond this range (m) scanned every time (0: none)

    void share(const SectionLookup &c) { road.share(c); }
    void bind(ParamMap &m) {
        m.add("model", model, nullptr,
              "path of the OpenCV cascade XML; empty = the model shipped with Headway "
              "(app/models/vehicle_cascade.xml, recipe in docs/detection.md)");
        m.add("verifier", verifier, nullptr,
              "verifier of every cascade detection: *.onnx = a CNN on the box's crop, *.yml(.gz) = HOG + one hidden "
              "layer; empty = app/models/vehicle_verifier.onnx; off = the window count as confidence");
        road.bind(m);
        m.add("min_vehicle_height_m", min_vehicle_height_m, 0.3, 5.0,
              "m; lowest vehicle box on a flat road; with the camera height it bounds how far below the "
              "horizon a window of each size is scanned (the highest: vehicle_shape.max_height_m); 1.0 m: a low car");
        m.add("scale_factor", scale_factor, 1.01, 2.0,
              "ratio between successive window sizes; smaller finds more sizes at more cost");
        m.add("max_window_frac", max_window_frac, 0.05, 1.0,
              "fraction of the image height; largest window scanned (a car at 5 m is about a third of the image wide)");
        m.add("min_window_px", min_window_px, 0.0, 1000.0,
              "px of the image; window sizes below this height are not scanned (0 = all, from the model's own "
              "20 px): smaller vehicles are not wanted, and the smallest sizes are the costliest to scan");
        m.add("step_px", step_px, 1, 8, "px of the resized band between windows; 2 as OpenCV's detectMultiScale");
        m.add("threads", threads, 1, 16,
              "threads the stage runs on (window sizes and verifier crops shared, the same results as one thread), "
              "at most the cores the process may use; 1 = the calling thread only (docs/detection.md)");
        m.add("scan_lanes", scan_lanes, 0, 8,
              "windows the own scanner evaluates at once: 0 = the widest this CPU has (8 with AVX2, else 4), 4 = "
              "SSE2, 8 = AVX2; the same detections either way (for tests and CPUs without AVX2)");
        m.add("opencv_scan", opencv_scan,
              "true = every band is scanned by OpenCV's cv::CascadeClassifier (the reference the own scanner, "
              "detect/cascade/haar_cascade.hpp, reproduces window for window; slower, step 2 only)");
        m.add("verifier_dnn", verifier_dnn,
              "true = run the CNN verifier by cv::dnn (the reference) instead of the core's own forward pass, with "
              "the same answers within 1e-5");
        m.add("group_iou", group_iou, 0.05, 0.95,
              "IoU; raw windows overlapping a group's strongest window at least this much join the group "
              "(docs/detection.md)");
        m.add("min_neighbors", min_neighbors, 1, 100, "raw windows; groups with fewer are dropped");
        m.add("neighbors_half", neighbors_half, 0.5, 100.0,
              "raw windows; a group of n windows has confidence n / (n + neighbors_half)");
        m.add("verify_min_neighbors", verify_min_neighbors, 0, 100,
              "raw windows; groups of fewer are not judged by the verifier and keep the confidence n / (n + "
              "neighbors_half); 0 = every group verified");
        m.add("max_groups", max_groups, 0, 10000,
              "groups kept and verified, those with the highest last-stage sum; 0 = all (fewer save verifier time "
              "but lose vehicles, docs/detection.md)");
        m.add("refine_boxes", refine_boxes,
              "true = a verifier with a box output moves each group's box onto the vehicle before the suppression "
              "(docs/detection.md); false = the group's mean box");
        m.add("rejudge_refined", rejudge_refined,
              "true = a moved box (refine_boxes) is judged again on its new crop and keeps the lower probability "
              "(docs/detection.md)");
        m.add("rejudge_min_p", rejudge_min_p, 0.0, 1.0,
              "probability; with rejudge_refined only the moved boxes the first look scores at least this are "
              "judged again; 0 = every moved box");
        m.add("rejudge_move", rejudge_move, 0.0, 1.0,
              "share of the second look's box offsets applied to a moved box (0 = keep the first look's box, 1 = "
              "the whole second step; docs/detection.md)");
        m.add("lazy_rejudge", lazy_rejudge,
              "true = with rejudge_refined and the suppression, a moved box that overlaps (nms_iou) a box already "
              "judged twice and still more confident than it gets no second look: the suppression drops it anyway "
              "(docs/detection.md); false = every believed box judged again");
        m.add("verify_mirrored", verify_mirrored,
              "true = the CNN verifier also judges the mirror image of each believed crop (mirror_min_p) and "
              "averages the two answers (docs/detection.md)");
        m.add("mirror_min_p", mirror_min_p, 0.0, 1.0,
              "probability; with verify_mirrored only the crops the plain look scores at least this are judged "
              "mirrored too");
        m.add("nms_iou", nms_iou, 0.05, 1.0,
              "IoU; after scoring, a detection overlapping a more confident one at least this much is dropped (a "
              "second group on the same vehicle); 0.3 measured best at high precision on the TuSimple validation "
              "split (docs/detection.md); 1 = keep all");
        m.add("tracked_slices", tracked_slices, 1, 32,
              "in a tracked pipeline the scan is cut into this many blocks of window sizes, one per full detection "
              "(more lose far cars, docs/detection.md); 1 = every size every time; single images scan all");
        m.add("tracked_far_m", tracked_far_m, 0.0, 1000.0,
              "m; with tracked_slices > 1, the window sizes of a car farther than this are scanned on every full "
              "detection and only the nearer sizes are sliced; 0 = every size sliced");
        m.add("border_frac", border_frac, 0.0, 0.5,
              "share of a window's width that may lie beyond the image's left or right border, so that a vehicle "
              "the border cuts is found (docs/detection.md); 0 = inside the image only");
    }
};

struct CascadeDetection {
    cv::Rect2f box;     // px, whole vehicle as annotated
    cv::Rect2f placed;  // px; where the verifier's box output puts it (= box without one): what the suppression compares
    int neighbors = 0;  // raw windows grouped
    float stage_sum = 0.f;  // the strongest window's last-stage sum
    float confidence = 0.f; // 0..1: the verifier's probability, or from neighbors without one
};

class VehicleVerifier;
class HaarCascade;
class WorkerPool;

class CascadeDetector {
public:
    explicit CascadeDetector(const CascadeParams &p);
    ~CascadeDetector();
    // Vehicles in a gray image; the camera is scaled to the image size.
    // `slice` of `slices`: only that block of the window sizes is scanned (contiguous sizes of about equal cost,
    // smallest first; tracked_slices), with the far sizes (tracked_far_m) every time; 0 of 1 = every size.
    // `times`: where the call's time goes, as two stages: "cascade" (the scan, grouping and suppression) and
    // "verifier" (the verifier's looks at the groups), so that a bench shows which of the two a budget needs.
    std::vector<CascadeDetection> detect(const cv::Mat &gray, const LaneModel &lanes, const CameraParams &cam,
                                         int slice = 0, int slices = 1,
                                         StageTimes *times = nullptr) const;

private:
    // detect()'s two halves: the scan and grouping of the windows (stage "cascade"), then the verifier's looks at the
    // groups ("verifier") and the suppression ("cascade")
    std::vector<CascadeDetection> groups(const cv::Mat &gray, const LaneModel &lanes, const CameraParams &cam,
                                         int slice, int slices, StageTimes *times) const;
    std::vector<CascadeDetection> judge(const cv::Mat &gray, const CameraParams &cam, std::vector<CascadeDetection> out,
                                        StageTimes *times) const;

    CascadeParams p_;
    std::unique_ptr<HaarCascade> haar_;          // the scan, unless opencv_scan
    std::vector<std::unique_ptr<HaarCascade>> helpers_;  // one more per thread (their scratch is their own)
    std::unique_ptr<cv::CascadeClassifier> cc_;  // only with opencv_scan
    std::unique_ptr<WorkerPool> pool_;           // the scan's sizes and the verifier's crops (threads)
    std::unique_ptr<VehicleVerifier> verifier_;  // null: verifier "off"
    cv::Size win_;
};

} // namespace hw
