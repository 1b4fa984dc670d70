// vehicle_verifier.hpp - the second learned stage: is a detected box a vehicle?
//
// Features x: the HOG of the box resized to the model's window (cv::HOGDescriptor, 16 px blocks, 8 px
// cells and stride, 9 bins), then log(1 + n) of the n raw cascade windows grouped, then the vehicle
// height the box implies on a flat road, H = h_cam * h / (y_b - y_h) (m; 10 when the bottom is not below
// the horizon; clipped to 0..10). Standardised, they go through a one-hidden-layer network trained by
// `headway train verifier` (app/train/verifier.py) on the cascade's own detections in training images:
//     z = (x - mean) .* scale,   p = sigmoid(w2 . relu(W1^T z + b1) + b2)
// The model file is written with cv::FileStorage (hog_width, hog_height, mean, scale, w1, b1, w2, b2).
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/objdetect.hpp>

#include <string>

namespace hw {

class VehicleVerifier {
public:
    explicit VehicleVerifier(const std::string &path);  // throws std::invalid_argument naming the file
    // Probability that `box` (px, clipped to the image), a group of `neighbors` raw cascade windows,
    // holds a vehicle; the camera's horizon row (px) and height (m) give the implied vehicle height.
    float probability(const cv::Mat &gray, const cv::Rect2f &box, int neighbors, double horizon_row,
                      double cam_height_m) const;

private:
    cv::HOGDescriptor hog_;
    cv::Mat mean_, scale_;  // 1 x d, float
    cv::Mat w1_;            // d x hidden, float
    cv::Mat b1_;            // 1 x hidden, float
    cv::Mat w2_;            // 1 x hidden, float
    float b2_ = 0.f;
};

} // namespace hw
