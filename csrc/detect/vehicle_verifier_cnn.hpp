// vehicle_verifier_cnn.hpp - the convolutional verifier: a small CNN on each detection's crop, run by cv::dnn.
//
// Trained by `headway train verifier --out X.onnx` (app/train/verifier_cnn.py, JAX) and written as ONNX
// (app/train/verifier_onnx.py, which also holds the network's equations). Its inputs, computed here exactly
// as the trainer computes them:
// - crop (N, 1, kCropH, kCropW): the box widened by kMargin of its size each side, rounded to whole pixels
//   (floor(v + 0.5)), the part outside the image filled by replicating the border, resized to kCropW x kCropH
//   (INTER_AREA), standardised by its own mean and standard deviation, z = (c - mean) / (std + 1);
// - extra (N, 2): log(1 + n) of the n raw cascade windows grouped, and implied_vehicle_height.
// Output p (N, 1): the probability that the box holds a vehicle. All the boxes of a frame go through the
// network in one batch.
#pragma once

#include "detect/vehicle_verifier.hpp"

#include <opencv2/dnn.hpp>

namespace hw {

class CnnVerifier : public VehicleVerifier {
public:
    static constexpr int kCropW = 48, kCropH = 32;  // px: the cascade's aspect 1.5
    static constexpr double kMargin = 0.1;          // of the box's width (height) added each side: context

    explicit CnnVerifier(const std::string &path);  // throws std::invalid_argument naming the file
    std::vector<float> probabilities(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes,
                                     const std::vector<int> &neighbors, double horizon_row,
                                     double cam_height_m) const override;
    // The standardised crop of one box (kCropH x kCropW, float), as the network takes it.
    static cv::Mat crop(const cv::Mat &gray, const cv::Rect2f &box);

private:
    mutable cv::dnn::Net net_;  // forward() is not const; one verifier serves one pipeline thread
};

} // namespace hw
