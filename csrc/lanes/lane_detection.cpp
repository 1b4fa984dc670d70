// lane_detection.cpp - the lane markings of one frame: filter, Hough, consensus, assignment.
#include "lanes/lane_tracker.hpp"

#include "lanes/road_gray.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace hw {

namespace {

void check_frame(const cv::Mat &gray, const CameraParams &cam) {
    if (gray.empty() || gray.type() != CV_8UC1)
        throw std::invalid_argument("lanes: expected a non-empty 8-bit gray image");
    if (gray.cols != cam.width || gray.rows != cam.height)
        throw std::invalid_argument("lanes: frame is " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows) +
                                    " but the camera is configured for " + std::to_string(cam.width) + "x" +
                                    std::to_string(cam.height));
}

std::vector<LaneCandidate> hough_candidates(const std::vector<MarkingPoint> &pts, const ScanBand &band,
                                            cv::Size size, const CameraParams &cam, const HorizonPrior &hp,
                                            const LaneParams &p, const HoughWindow &win) {
    std::vector<LaneCandidate> out;
    for (const auto &l : hough_lane_lines(pts, band, size, cam, hp, p.hough, win)) {
        LaneCandidate c;
        c.line = l.line;
        c.weight = l.votes;
        c.fit = l.fit;
        out.push_back(c);
    }
    return out;
}

// Keeps the lines through the consensus vanishing point (if any), which is written to vp.
bool keep_consensus(std::vector<LaneCandidate> &lines, const HorizonPrior &hp, cv::Size size,
                    const LaneAssemblyParams &p, cv::Point2f &vp) {
    std::vector<char> inlier;
    if (!consensus_vanishing_point(lines, hp, size, p, vp, inlier)) return false;
    std::vector<LaneCandidate> kept;
    for (size_t i = 0; i < lines.size(); ++i)
        if (inlier[i]) kept.push_back(lines[i]);
    lines.swap(kept);
    return true;
}

} // namespace

// Two passes: the strong lines in a wide window give the vanishing point by consensus (skipped
// when the caller knows it), then every marking is searched in a narrow window around it.
LaneMeasurement measure_lane_lines(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam,
                                   const HorizonPrior &hp, const cv::Point2f *known_vp,
                                   const std::vector<cv::Rect2f> *vehicles, bool tracking) {
    check_frame(gray, cam);
    LaneMeasurement m;
    const ScanBand band = scan_band(gray.size(), cam, hp, p.filter);
    if (band.rows() < 2) return m;
    std::vector<MarkingPoint> &pts = m.points;
    const bool dots = p.dots.enabled && (!tracking || p.dots.in_tracking);
    std::vector<MarkingPoint> short_bars;
    find_marking_points(gray, band, cam, hp, p.filter, pts, dots ? &short_bars : nullptr, !tracking);
    const float frac = float(p.vehicle_mask_frac);  // upper part of each box: the vehicle's body
    auto on_vehicle = [&](const MarkingPoint &q) {
        for (const auto &b : *vehicles)
            if (q.x >= b.x && q.x <= b.x + b.width && q.y >= b.y && q.y <= b.y + frac * b.height) return true;
        return false;
    };
    if (vehicles && !vehicles->empty()) {
        pts.erase(std::remove_if(pts.begin(), pts.end(), on_vehicle), pts.end());
        short_bars.erase(std::remove_if(short_bars.begin(), short_bars.end(), on_vehicle), short_bars.end());
    }

    // Botts' dots lined up toward the expected vanishing point (the wide search's window) join the points, so the
    // wide search's consensus and the narrow search both see dotted lines.
    if (dots)
        add_dot_markings(gray, short_bars, band, cam, hp, p.dots,
                         float(p.hough.max_vp_offset_frac * gray.cols) + hp.tol_px, pts);
    // Narrow search around vp: the lines through it, with the vanishing point refined by them.
    auto narrow = [&](cv::Point2f vp, bool tracked) {
        m.lines = hough_candidates(pts, band, gray.size(), cam, hp, p, vp_window(vp, tracked, gray.size(), p.hough));
        cv::Point2f refined;
        m.vp = keep_consensus(m.lines, hp, gray.size(), p.assembly, refined) ? refined : vp;
    };
    if (known_vp) {
        narrow(*known_vp, true);
        if (m.lines.size() >= 2) return m;
    }
    // The vanishing point of this frame (or the known one found too little: it moved, or the road
    // changed): consensus of the strong lines of a wide search.
    std::vector<LaneCandidate> wide =
        hough_candidates(pts, band, gray.size(), cam, hp, p, wide_window(gray.size(), hp, p.hough));
    cv::Point2f vp;
    if (keep_consensus(wide, hp, gray.size(), p.assembly, vp)) {
        narrow(vp, false);
        if (m.lines.empty()) m.lines = wide;
    } else {
        m.lines = wide;  // no two lines agree: keep them all, vanishing point unknown
        m.vp = {kNaN, kNaN};
    }
    return m;
}

LaneModel detect_lanes(const cv::Mat &gray, const LaneParams &p, const CameraParams &cam) {
    const HorizonPrior hp = camera_horizon(cam, p.assembly.horizon_tolerance_deg);
    const LaneMeasurement m = measure_lane_lines(gray, p, cam, hp);
    const LaneAssignment a = assign_lanes(m.lines, cam, p.assembly);
    LaneModel out;
    build_lane_model(m.lines, a, m.vp, gray.size(), cam, hp, p.assembly, out);
    out.frames_since_observed = out.valid ? 0 : 1;
    LaneCurveState curve;  // one image: no curvature history
    // The curve fit takes paint, brighter than the road (curve_single_above_road): the road between a concrete seam
    // and a shadow is a bright bar to the marking filter at the road's own gray.
    std::vector<MarkingPoint> paint;
    const std::vector<MarkingPoint> *fit_points = &m.points;
    if (out.valid && p.curve.single_above_road > 0.0) {
        EgoRoadGray road(gray, out.ego_left, out.ego_right);
        for (const auto &q : m.points) {
            const int x = int(std::lround(q.x)), y = int(std::lround(q.y)), median = road.at(y);
            if (median < 0 || x < 0 || x >= gray.cols ||
                gray.at<uint8_t>(y, x) >= float(median) * (1.0 + p.curve.single_above_road))
                paint.push_back(q);
        }
        fit_points = &paint;
    }
    fit_lane_curves(*fit_points, std::isfinite(out.vanishing_point.y) ? out.vanishing_point.y : hp.row, cam,
                    float(p.assembly.road.lane_width_m), p.curve, curve, out, p.curve.single_shared_a);
    ego_lane_metrics(cam, out);
    // One image: outer boundaries need paint along the road in this frame, and nothing is reported beyond a
    // solid ego boundary (the carriageway's edge line), as over frames (lane_tracker.cpp): on TuSimple's 10-image
    // sample the right shoulder's edge beyond 0313-2/520's solid right line was a false lane (sample FP 0.175 ->
    // 0.158, nothing else moved; headway eval --parts lanes). The ego pair's evidence is judged over frames:
    // one image has no confirmed vehicles to mask and no smoothing over dash gaps (a dashed line can miss two of
    // the three range bins), so a single image's model is believed.
    const float y_h = std::isfinite(out.vanishing_point.y) ? out.vanishing_point.y : hp.row;
    const ScanBand band = scan_band(gray.size(), cam, hp, p.filter);
    drop_unsupported_outer(out, m.points, {}, y_h, float(band.y_bottom), cam, p.evidence);
    // An adjacent line darker than the road (a concrete joint with dots on it) where the model puts one; after the
    // paint check above (it has dark bars, no paint) and before the solid-edge rule (nothing beyond a solid line).
    add_dark_adjacent(gray, band, cam, hp, p.filter, p.dark, out);
    drop_beyond_solid_edges(out, m.points, {}, y_h, band, cam, p.evidence);
    out.certain = out.valid;
    return out;
}

} // namespace hw
