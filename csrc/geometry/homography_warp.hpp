// homography_warp.hpp - an image warped by a homography, as cv::warpPerspective (bilinear, borders
// replicated), computed as a map and one cv::remap.
//
// Why not cv::warpPerspective: on this project's machine it costs ~8 ns per pixel (it divides per
// pixel in double precision inside its blocks), twice per frame on the parallax preset's road band,
// ~1 ms of the 5 ms budget. The same map in single precision is a loop the compiler vectorises, and
// cv::remap with a float map costs what a warpAffine does (OpenCV on this machine, a 320 x 140 band:
// warpPerspective 0.34 ms, remap 0.13 ms); in the pipeline the parallax stage went from 2.22 to 1.80 ms
// (docs/PERFORMANCE.md). remap quantises the coordinates to 1/32 px as warpPerspective does.
#pragma once

#include <opencv2/core.hpp>

namespace hw {

// dst(x) = src(H^-1 x) over `size` (H maps src to dst, as cv::warpPerspective's M).
void warp_homography(const cv::Mat &src, const cv::Matx33d &H, cv::Size size, cv::Mat &dst);

} // namespace hw
