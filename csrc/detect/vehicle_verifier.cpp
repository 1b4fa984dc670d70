#include "detect/vehicle_verifier.hpp"
#include "detect/vehicle_verifier_cnn.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace hw {

float implied_vehicle_height(const cv::Rect2f &box, double horizon_row, double cam_height_m) {
    const double below = box.br().y - horizon_row;
    const double hv = below > 0 ? cam_height_m * box.height / below : 10.0;
    return float(std::clamp(hv, 0.0, 10.0));
}

std::unique_ptr<VehicleVerifier> make_vehicle_verifier(const std::string &path, bool mirrored, double mirror_min_p,
                                                       bool dnn) {
    const std::string ext = ".onnx";
    if (path.size() > ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0)
        return std::make_unique<CnnVerifier>(path, mirrored, mirror_min_p, dnn);
    return std::make_unique<HogVerifier>(path);
}

HogVerifier::HogVerifier(const std::string &path) {
    cv::FileStorage fs;
    try {
        fs.open(path, cv::FileStorage::READ);
    } catch (const cv::Exception &) {
    }
    if (!fs.isOpened())
        throw std::invalid_argument("cascade.verifier: cannot read '" + path +
                                    "'; train one with `headway train verifier` or set the key to off");
    const int w = int(fs["hog_width"]), h = int(fs["hog_height"]);
    fs["mean"] >> mean_;
    fs["scale"] >> scale_;
    fs["w1"] >> w1_;
    fs["b1"] >> b1_;
    fs["w2"] >> w2_;
    b2_ = float(fs["b2"]);
    if (w < 16 || h < 16 || (w - 16) % 8 || (h - 16) % 8 || w1_.empty() || b1_.empty() || w2_.empty())
        throw std::invalid_argument("cascade.verifier: '" + path + "' is not a verifier model (hog_width, hog_height, "
                                    "mean, scale, w1, b1, w2, b2); train one with `headway train verifier`");
    hog_ = cv::HOGDescriptor(cv::Size(w, h), cv::Size(16, 16), cv::Size(8, 8), cv::Size(8, 8), 9);
    for (cv::Mat *m : {&mean_, &scale_, &w1_, &b1_, &w2_}) m->convertTo(*m, CV_32F);
    const int d = int(hog_.getDescriptorSize()) + 2;  // HOG, log(1 + n), implied height
    if (mean_.total() != size_t(d) || scale_.total() != size_t(d) || w1_.rows != d ||
        b1_.total() != size_t(w1_.cols) || w2_.total() != size_t(w1_.cols))
        throw std::invalid_argument("cascade.verifier: '" + path + "' does not fit a HOG of " + std::to_string(d) +
                                    " values (mean, scale, w1 rows) or its hidden layer (b1, w2)");
    mean_ = mean_.reshape(1, 1);
    scale_ = scale_.reshape(1, 1);
    b1_ = b1_.reshape(1, 1);
    w2_ = w2_.reshape(1, 1);
}

std::vector<float> HogVerifier::probabilities(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes,
                                             const std::vector<int> &neighbors, double horizon_row,
                                             double cam_height_m, const cv::Mat *) const {
    std::vector<float> p(boxes.size());
    for (size_t i = 0; i < boxes.size(); ++i)
        p[i] = probability(gray, boxes[i], neighbors[i], horizon_row, cam_height_m);
    return p;
}

float HogVerifier::probability(const cv::Mat &gray, const cv::Rect2f &box, int neighbors, double horizon_row,
                                   double cam_height_m) const {
    const cv::Rect r = cv::Rect(cv::Point(int(std::lround(box.x)), int(std::lround(box.y))),
                                cv::Point(int(std::lround(box.br().x)), int(std::lround(box.br().y)))) &
                       cv::Rect(0, 0, gray.cols, gray.rows);
    if (r.width < 4 || r.height < 4) return 0.f;
    cv::Mat crop;
    cv::resize(gray(r), crop, hog_.winSize, 0, 0, cv::INTER_AREA);
    std::vector<float> x;
    hog_.compute(crop, x);
    x.push_back(float(std::log1p(double(neighbors))));
    x.push_back(implied_vehicle_height(box, horizon_row, cam_height_m));
    const cv::Mat z = (cv::Mat(1, int(x.size()), CV_32F, x.data()) - mean_).mul(scale_);
    cv::Mat hidden = z * w1_ + b1_;
    hidden = cv::max(hidden, 0.f);
    const double logit = hidden.dot(w2_) + b2_;
    return float(1.0 / (1.0 + std::exp(-logit)));
}

} // namespace hw
