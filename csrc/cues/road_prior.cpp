#include "cues/road_prior.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

namespace {

// The camera's intrinsics expressed for an image of `size` (identity when the sizes agree).
struct ScaledCamera {
    double fx, fy, cx, cy, height_m, horizon;
    double yaw_rad, lateral_m;
};

ScaledCamera scale_camera(const CameraParams &cam, cv::Size size) {
    const double sx = double(size.width) / cam.width, sy = double(size.height) / cam.height;
    ScaledCamera c{cam.fx * sx, cam.fy * sy, cam.cx * sx, cam.cy * sy, cam.height_m, 0.0,
                   cam.yaw_deg * M_PI / 180.0, cam.lateral_m};
    c.horizon = c.cy - c.fy * std::tan(cam.pitch_deg * M_PI / 180.0);
    return c;
}

// Both ego boundaries known and believed painted markings (lanes/lane_evidence.hpp): on an unmarked road
// the "lanes" are vehicle rears and barriers, and the camera's road is the better prior.
bool lanes_usable(const LaneModel &lanes) {
    return lanes.certain && lanes.ego_left.valid && lanes.ego_right.valid;
}

// Horizon row: the vanishing point of the lane model when it has one inside a sane band, else the
// camera's static pitch.
double horizon_row(const LaneModel &lanes, const ScaledCamera &c, cv::Size size) {
    const float vy = lanes.vanishing_point.y;
    if (lanes_usable(lanes) && std::isfinite(vy) && vy > -size.height && vy < size.height) return vy;
    return c.horizon;
}

// Flat-road width of a W-metre object whose bottom is at row y: (fx / fy) * W * (y - y_h) / h.
float flat_road_width(double y, double horizon, const ScaledCamera &c, double width_m) {
    return float(c.fx / c.fy * width_m * (y - horizon) / c.height_m);
}

// Polygon row crossing: the leftmost and rightmost x where the polygon's edges cross row y.
bool polygon_span(const std::vector<cv::Point> &poly, double y, double &xl, double &xr) {
    xl = 1e30; xr = -1e30;
    const size_t n = poly.size();
    for (size_t i = 0; i < n; ++i) {
        const cv::Point a = poly[i], b = poly[(i + 1) % n];
        if ((a.y <= y && b.y >= y) || (b.y <= y && a.y >= y)) {
            if (a.y == b.y) {
                xl = std::min({xl, double(a.x), double(b.x)});
                xr = std::max({xr, double(a.x), double(b.x)});
            } else {
                const double x = a.x + (b.x - a.x) * (y - a.y) / double(b.y - a.y);
                xl = std::min(xl, x); xr = std::max(xr, x);
            }
        }
    }
    return xl <= xr;
}

} // namespace

RoadPrior make_road_prior(cv::Size size, const LaneModel &lanes, const CameraParams &cam,
                          const RoadPriorParams &p) {
    if (size.width <= 0 || size.height <= 0) throw std::invalid_argument("make_road_prior: empty image");
    if (cam.width <= 0 || cam.height <= 0) throw std::invalid_argument("make_road_prior: camera size");
    const ScaledCamera c = scale_camera(cam, size);
    RoadPrior r;
    r.from_lanes = lanes_usable(lanes);
    const double yh = horizon_row(lanes, c, size);
    r.horizon_row = float(yh);
    // First scanned row: the ground row of a vehicle at max_range, y = y_h + fy * h / Z_max.
    r.y_top = std::max(2, int(std::ceil(yh + c.fy * c.height_m / p.max_range_m)));
    r.y_bottom = std::min(size.height - 2, cam.hood_row(size.height));
    if (r.empty()) return r;
    const int n = r.y_bottom - r.y_top;
    r.x_left.assign(n, 0); r.x_right.assign(n, -1); r.width_px.assign(n, 0.f);
    // Ego-lane centre line of the fallback: x = x_vp + fx * (-lateral_m) / Z, x_vp = cx - fx tan(yaw).
    const double x_vp = c.cx - c.fx * std::tan(c.yaw_rad);
    for (int i = 0; i < n; ++i) {
        const double y = r.y_top + i;
        const float w_cam = flat_road_width(y, yh, c, p.shape.width_m);
        double xl = 1e30, xr = -1e30;
        float w = w_cam;
        if (r.from_lanes) {
            const float el = lanes.ego_left.x_at(float(y)), er = lanes.ego_right.x_at(float(y));
            const float lw = er - el;
            if (std::isfinite(lw) && lw > 0.f) {
                w = float(lw * p.shape.width_m / p.road.lane_width_m);
                xl = el - p.adjacent_lanes * lw;
                xr = er + p.adjacent_lanes * lw;
            }
            double pl, pr;
            if (lanes.road_polygon.size() >= 3 && polygon_span(lanes.road_polygon, y, pl, pr)) {
                xl = std::min(xl, pl); xr = std::max(xr, pr);
            }
        } else if (w_cam > 0.f) {
            const double scale = w_cam / p.shape.width_m;  // px per metre at this row = fx / Z
            xl = x_vp + scale * (-c.lateral_m - p.road_half_width_m);
            xr = x_vp + scale * (-c.lateral_m + p.road_half_width_m);
        }
        if (!(w > 0.f) || xl > xr) continue;
        r.width_px[i] = w;
        r.x_left[i] = std::max(1, int(std::floor(xl)));
        r.x_right[i] = std::min(size.width - 2, int(std::ceil(xr)));
    }
    return r;
}

float horizon_row(cv::Size size, const LaneModel &lanes, const CameraParams &cam) {
    return float(horizon_row(lanes, scale_camera(cam, size), size));
}

cv::Point2f vanishing_point(cv::Size size, const LaneModel &lanes, const CameraParams &cam) {
    const ScaledCamera c = scale_camera(cam, size);
    const float yh = float(horizon_row(lanes, c, size));
    const float vx = lanes.vanishing_point.x;
    if (lanes_usable(lanes) && std::isfinite(vx) && std::abs(vx - 0.5f * size.width) < size.width) return {vx, yh};
    return {float(c.cx - c.fx * std::tan(c.yaw_rad)), yh};
}

float expected_vehicle_width(float y, cv::Size size, const LaneModel &lanes, const CameraParams &cam,
                             const RoadPriorParams &p) {
    const ScaledCamera c = scale_camera(cam, size);
    if (lanes_usable(lanes)) {
        const float lw = lanes.lane_width_px(y);
        if (std::isfinite(lw) && lw > 0.f) return float(lw * p.shape.width_m / p.road.lane_width_m);
    }
    return flat_road_width(y, horizon_row(lanes, c, size), c, p.shape.width_m);
}

} // namespace hw
