// road_motion_fit.hpp - the road plane's homography between two frames, restricted to how a car's
// camera moves over a flat road: a small rotation (pitch, yaw, roll: shake, turning) and a translation
// (travel along the road, a lateral shift), through the camera model's intrinsics and mounting.
//
// The DLT's eight degrees of freedom are fixed by the correspondences on the lane markings only: where
// there are none (the far side of the image when vehicles hide the markings there) it extrapolates
// freely, and on the shaken synthetic dense_traffic road put road points on the image's right side
// 15-20 px off while the ego lane aligned to a pixel or two. With five physical parameters every road
// point moves as the plane does, including where no marking is seen.
//
// Model (camera axes x right, y down, z forward; level-camera road plane n^T X = h, n = (0, 1, 0)):
//     x' ~ K R_d R_c (I - t n^T / h) R_c^T K^-1 x,   t = (lateral, 0, travel),
// R_c the mounting (pitch, yaw of CameraParams), R_d = Rodrigues(pitch_d, yaw_d, roll_d) the rotation
// between the frames. Fitted by Gauss-Newton on the transfer error of the correspondences the DLT kept
// (those within trim_factor medians of its transfer error), started at rest.
//
// With free_tilt the road plane's tilt e against the assumed mounting is a sixth parameter: the plane is
// n^T X = h with n = (0, cos e, sin e) in the assumed level-camera axes, n = R_c^T R_true (0, 1, 0), so for
// a mounting pitched e more than assumed (down positive). Why it is observable in one frame pair: on a level
// camera a road point at normalised row v (depth h / v) moves by dv = (t_z / h) v^2 over a travel t_z; a
// tilt moves the zero of that flow to the true horizon, dv = (t_z / h) (v + e)^2 = (t_z / h)(v^2 + 2 e v + e^2),
// and du = (t_z / h) u (v + e): the linear terms 2 e v t_z / h and e u t_z / h are told apart from a
// rotation (flow ~ constant in v) and the travel (~ v^2) by the spread of rows and columns of the
// markings. Needs travel (t_z / h of a few per cent) and is the local road plane's (the markings 5-40 m).
#pragma once

#include "geometry/camera.hpp"
#include "geometry/homography_dlt.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

// theta = (pitch_d, yaw_d, roll_d [rad], lateral_m, travel_m) -> homography, H(2,2) = 1; tilt_rad: the
// road plane's tilt e against the assumed mounting (0: the plane the mounting says).
cv::Matx33d road_motion_homography(const CameraParams &cam, const cv::Vec<double, 5> &theta, double tilt_rad = 0.0);

// R_c of the model: the camera's mounting, yaw about y then pitch about x (level-camera -> camera axes).
cv::Matx33d mounting_rotation(const CameraParams &cam);

// The translation t (m, level-camera axes: x right, y down, z forward) of a road homography of the model's
// form, for the camera it was fitted with: M = R_c^T K^-1 H K R_c = s R' (I - t n^T / h), n = (0, 1, 0), R' a
// rotation. M's first and third columns are s R''s (n has no x or z part), so s = |M_0|,
// R' = [M_0, M_2 x M_0, M_2] / s, and t / h = e_y - R'^T M_1 / s. NaNs when H is degenerate.
cv::Vec3d road_motion_translation(const cv::Matx33d &H, const CameraParams &cam);
// R' of the same decomposition: the camera's rotation between the frames in level-camera axes (identity
// when H is degenerate).
cv::Matx33d road_motion_rotation(const cv::Matx33d &H, const CameraParams &cam);

struct RoadMotionFit {
    bool ok = false;
    cv::Matx33d H = cv::Matx33d::eye();
    cv::Vec<double, 5> theta;
    int used = 0;
    double rms_px = 0.0;
    // free_tilt only: the six-parameter fit continued from this one (the fields above stay the five-parameter
    // fit's): whether it explained the correspondences within max_rms_px, the plane's tilt e (rad, true pitch -
    // assumed pitch) and its travel (m, for the assumed height)
    bool tilt_ok = false;
    double tilt_rad = NAN, tilt_travel_m = NAN;
};

// The road-motion homography closest to the correspondences that `dlt` (a DLT of them) explains
// within DltParams' trimming; ok when it explains them within max_rms_px.
// free_tilt: the plane's tilt is then fitted too (six parameters, RoadMotionFit::tilt_*).
RoadMotionFit fit_road_motion(const std::vector<cv::Point2f> &from, const std::vector<cv::Point2f> &to,
                              const cv::Matx33d &dlt, const CameraParams &cam, const DltParams &p,
                              bool free_tilt = false);

} // namespace hw
