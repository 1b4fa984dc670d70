// vehicle_verifier.hpp - the second learned stage: is a detected box a vehicle?
//
// HOG of the box resized to the model's window (cv::HOGDescriptor, 16 px blocks, 8 px cells and
// stride, 9 bins) and a logistic regression trained by `headway train verifier` on the cascade's own
// detections in the training images: p = 1 / (1 + exp(-(w . x + b))). The model file is written with
// cv::FileStorage (hog_width, hog_height, weights, bias).
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/objdetect.hpp>

#include <string>

namespace hw {

class VehicleVerifier {
public:
    explicit VehicleVerifier(const std::string &path);  // throws std::invalid_argument naming the file
    // Probability that `box` (px, clipped to the image) holds a vehicle.
    float probability(const cv::Mat &gray, const cv::Rect2f &box) const;

private:
    cv::HOGDescriptor hog_;
    cv::Mat weights_;  // 1 x n, float
    float bias_ = 0.f;
};

} // namespace hw
