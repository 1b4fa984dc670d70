#include "detect/vehicle_verifier.hpp"

#include <opencv2/imgproc.hpp>

#include <cmath>
#include <stdexcept>
#include <vector>

namespace hw {

VehicleVerifier::VehicleVerifier(const std::string &path) {
    cv::FileStorage fs;
    try {
        fs.open(path, cv::FileStorage::READ);
    } catch (const cv::Exception &) {
    }
    if (!fs.isOpened())
        throw std::invalid_argument("cascade.verifier: cannot read '" + path +
                                    "'; train one with `headway train verifier` or set the key to off");
    const int w = int(fs["hog_width"]), h = int(fs["hog_height"]);
    fs["weights"] >> weights_;
    fs["bias"] >> bias_;
    if (w < 16 || h < 16 || weights_.empty())
        throw std::invalid_argument("cascade.verifier: '" + path + "' is not a verifier model (hog_width, hog_height, weights, bias)");
    hog_ = cv::HOGDescriptor(cv::Size(w, h), cv::Size(16, 16), cv::Size(8, 8), cv::Size(8, 8), 9);
    weights_.convertTo(weights_, CV_32F);
    weights_ = weights_.reshape(1, 1);
    if (size_t(weights_.cols) != hog_.getDescriptorSize())
        throw std::invalid_argument("cascade.verifier: '" + path + "' has " + std::to_string(weights_.cols) +
                                    " weights for a HOG of " + std::to_string(hog_.getDescriptorSize()) + " values");
}

float VehicleVerifier::probability(const cv::Mat &gray, const cv::Rect2f &box) const {
    const cv::Rect r = cv::Rect(cv::Point(int(std::lround(box.x)), int(std::lround(box.y))),
                                cv::Point(int(std::lround(box.br().x)), int(std::lround(box.br().y)))) &
                       cv::Rect(0, 0, gray.cols, gray.rows);
    if (r.width < 4 || r.height < 4) return 0.f;
    cv::Mat crop;
    cv::resize(gray(r), crop, hog_.winSize, 0, 0, cv::INTER_AREA);
    std::vector<float> x;
    hog_.compute(crop, x);
    const double z = weights_.dot(cv::Mat(1, int(x.size()), CV_32F, x.data())) + bias_;
    return float(1.0 / (1.0 + std::exp(-z)));
}

} // namespace hw
