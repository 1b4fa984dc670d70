// birth_gate.hpp - whether a detection that no track took may start a vehicle: not when it lies on a vehicle that
// is already tracked.
//
// A detection overlapping a tracked vehicle's box (IoU >= explained_iou), or whose foot (bottom centre) stands inside
// that box, is part of that vehicle (a window, a bumper, the road's shadow under it). Optionally (beside_overlap < 1)
// one standing on the vehicle's own bottom row and overlapping its columns is beside it, not another vehicle: two
// vehicles at one range cannot overlap in the image. Optionally (nearer_below > 0) a detection across a tracked box's
// columns whose bottom stands well below that box's (a nearer vehicle, in front of it) is not explained by it: a
// vehicle is not part of one it hides.
#pragma once

#include <opencv2/core.hpp>

#include <vector>

namespace hw {

struct BirthGateParams {
    double explained_iou = 0.2;     // IoU with a tracked vehicle's box from which a detection is part of it
    double beside_overlap = 1.0;    // share of the narrower width; columns overlapping this much on one bottom row
                                    // are the same vehicle (1 = that rule off)
    double beside_bottom_tol = 0.2;  // narrower widths; bottom rows at most this far apart are one range
    double nearer_below = 0.0;      // tracked box heights; a detection standing this much lower than a tracked box and
                                    // across its columns is a nearer vehicle in front of it, not part of it (0 = off)
};

// True when the detection `det` is explained by one of the `tracked` boxes (see above): it starts no vehicle.
bool on_tracked_vehicle(const cv::Rect2f &det, const std::vector<cv::Rect2f> &tracked, const BirthGateParams &p);

} // namespace hw
