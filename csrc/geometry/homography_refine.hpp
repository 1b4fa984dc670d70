// homography_refine.hpp - the road homography refined on the road pixels themselves.
//
// The filtered homography comes from marking corners 5-50 m ahead; extrapolated to the far road
// (60-80 m, a few tens of rows below the horizon) its error grows to a pixel or more (measured on TME
// tme08: 1-1.5 px of vertical misalignment 60-70 m ahead, 0.25-0.5 px near), while a vehicle keeping
// its distance there shows less parallax than that. Road pixels everywhere hold texture, so the
// two motions the marking fit gets wrong at range are measured directly on them: a vertical shift d
// (pitch) and an extra travel s, whose flows are
//     shift   (0, d)
//     travel  ((x - x_v)(y - y_h), (y - y_h)^2) s / (f_y h)          (road point at range f_y h / (y - y_h))
// Each Gauss-Newton step warps the previous road band with H, linearises the residual
//     r = I_k - warp(I_{k-1}) ~ -grad(I) . (flow_d d + flow_s s) + b0 + b1 v + b2 v^2
// (b: the brightness change between the frames along the rows, photometric.hpp) and solves the 5x5
// normal equations over the road pixels whose |r| is below outlier_gray (vehicles and structures above
// the road differ more and are left out); then H <- F(s) S(d) H, S the vertical shift, F the exact
// travel homography about the vanishing point. Corrections beyond max_shift_px / max_travel_m are
// refused (the refinement only polishes).
#pragma once

#include "core/params.hpp"
#include "geometry/camera.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct HomographyRefineParams {
    int iterations = 0;           // Gauss-Newton steps (0: no refinement, the default: see bind())
    double outlier_gray = 12.0;   // gray levels; pixels with a larger |residual| are left out
    double max_shift_px = 4.0;    // px; largest vertical shift accepted per step
    double max_travel_m = 0.5;    // m; largest extra travel accepted per step

    void bind(ParamMap &m);
};

struct HomographyRefinement {
    bool ok = false;
    double shift_px = 0.0;   // total vertical shift applied, full-resolution px
    double travel_m = 0.0;   // total extra travel applied, m
    cv::Matx33d H = cv::Matx33d::eye();  // refined, previous -> current pixels
};

// cur_band / prev_band: the road band (rows band_top ..) of both frames at pyramid level `level`;
// road: the road polygon in full-resolution pixels (empty = every band row below the horizon);
// vp: the road's vanishing point (its row is the horizon).
HomographyRefinement refine_road_homography(const cv::Mat &cur_band, const cv::Mat &prev_band, int band_top, int level,
                                            const cv::Matx33d &H, const std::vector<cv::Point> &road, cv::Point2f vp,
                                            const CameraParams &cam, const HomographyRefineParams &p);

} // namespace hw
