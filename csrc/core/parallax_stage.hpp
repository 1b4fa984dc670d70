// parallax_stage.hpp - the two-frame units of the parallax pipeline, reachable alone through
// Pipeline::run_stage (and so through hw_pipeline_run_stage), without touching tracking state.
//
// The image passed is K >= 2 frames of the camera's size stacked vertically, oldest on top; a fresh
// lane tracker, road-motion stage, parallax detector and particle tracker run over them (nominal 30 fps,
// no ego speed), and the result describes the last pair:
//   "homography"  full_detection = the last pair's homography measurement was accepted by the gate;
//                 image_change   = the alignment residual: mean |I_K - warp(I_{K-1}, H) - o| over the ego
//                                  lane up to 40 m (the road area without a lane model), outside the
//                                  detections and the bonnet (gray levels), o the smooth brightness
//                                  change between the two images fitted on those pixels (photometric.hpp);
//                 image_mean     = the same without alignment, |I_K - I_{K-1} - o'|, over the same pixels;
//                 image_stddev   = the aligned residual with the brightness change left in, |I_K - warp(I_{K-1}, H)|;
//                 lanes, vanishing point: the last frame's lane model; no tracks.
//   "parallax"    as "homography", plus one track per measurement region of the last pair (box from
//                 the region, confidence = its mean |difference| / 64, capped at 1), unconfirmed.
// With K > 2 the homography filter has K - 2 frames to settle before the last pair is judged.
#pragma once

#include "base/types.hpp"
#include "core/config.hpp"

#include <string>

namespace hw {

bool is_parallax_stage(const std::string &stage);

FrameOutput run_parallax_stage(const std::string &stage, const cv::Mat &stacked, const Config &cfg);

} // namespace hw
