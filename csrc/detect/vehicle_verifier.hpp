// vehicle_verifier.hpp - the second learned stage: is a detected box a vehicle?
//
// Two kinds, chosen by the model file's name (make_vehicle_verifier):
// - *.onnx: a small convolutional network on the box's crop (vehicle_verifier_cnn.hpp), by its own forward pass;
// - otherwise (*.yml, *.yml.gz): HogVerifier below.
// Both take, besides the image, log(1 + n) of the n raw cascade windows grouped and the vehicle height the
// box implies on a flat road (implied_vehicle_height).
//
// HogVerifier. Features x: the HOG of the box resized to the model's window (cv::HOGDescriptor, 16 px
// blocks, 8 px cells and stride, 9 bins), then log(1 + n), then the implied height. Standardised, they go
// through a one-hidden-layer network trained by `headway train verifier` (app/train/verifier.py) on the
// cascade's own detections in training images:
//     z = (x - mean) .* scale,   p = sigmoid(w2 . relu(W1^T z + b1) + b2)
// The model file is written with cv::FileStorage (hog_width, hog_height, mean, scale, w1, b1, w2, b2).
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/objdetect.hpp>

#include <memory>
#include <string>
#include <vector>

namespace hw {

class WorkerPool;

// The vehicle height (m) a box implies on a flat road, H = h_cam h / (y_b - y_h); 10 when its bottom is not
// below the horizon; clipped to 0..10.
float implied_vehicle_height(const cv::Rect2f &box, double horizon_row, double cam_height_m);

class VehicleVerifier {
public:
    virtual ~VehicleVerifier() = default;
    // Probability that each box (px, clipped to the image), a group of neighbors[i] raw cascade windows,
    // holds a vehicle; the camera's horizon row (px) and height (m) give the implied vehicle height. `integral`:
    // integral_of(gray), made once by a caller that judges the same image several times; null: the verifier makes
    // it where it needs it.
    virtual std::vector<float> probabilities(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes,
                                             const std::vector<int> &neighbors, double horizon_row,
                                             double cam_height_m, const cv::Mat *integral = nullptr) const = 0;
    // probabilities(), and for a verifier with a box output (a CNN trained with one) each box moved onto the
    // vehicle as that output says; a verifier without one leaves the boxes as they are.
    virtual std::vector<float> judge(const cv::Mat &gray, std::vector<cv::Rect2f> &boxes,
                                     const std::vector<int> &neighbors, double horizon_row, double cam_height_m,
                                     const cv::Mat *integral = nullptr) const {
        return probabilities(gray, boxes, neighbors, horizon_row, cam_height_m, integral);
    }
    // true when judge() moves boxes (a box output)
    virtual bool has_box_output() const { return false; }
    // What a verifier reads its crops from, for the `integral` argument above: the image's integral (CV_32S) for a
    // verifier that averages its crops from it, else empty.
    virtual cv::Mat integral_of(const cv::Mat &) const { return {}; }
    // the threads its network may share the crops among (base/worker_pool.hpp; not owned, null: the calling thread
    // alone); verifiers without one ignore it
    virtual void set_pool(WorkerPool *) {}
};

// The verifier the file holds (.onnx: CnnVerifier, else HogVerifier); throws std::invalid_argument naming it.
// `mirrored`: a CnnVerifier also judges the mirror image of each crop it gives at least `mirror_min_p` and averages
// the two (CnnVerifier); a HogVerifier judges the crop as it is. `dnn`: a CnnVerifier's network is run by cv::dnn
// rather than its own forward pass (verifier_net.hpp).
std::unique_ptr<VehicleVerifier> make_vehicle_verifier(const std::string &path, bool mirrored = false,
                                                       double mirror_min_p = 0.0, bool dnn = false);

class HogVerifier : public VehicleVerifier {
public:
    explicit HogVerifier(const std::string &path);  // throws std::invalid_argument naming the file
    std::vector<float> probabilities(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes,
                                     const std::vector<int> &neighbors, double horizon_row, double cam_height_m,
                                     const cv::Mat *integral = nullptr) const override;
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
