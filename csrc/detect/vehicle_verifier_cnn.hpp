// vehicle_verifier_cnn.hpp - the convolutional verifier: a small CNN on each detection's crop.
//
// cv::dnn reads the file; the network then runs by its own forward pass (verifier_net.hpp: the trainer's one
// architecture, 3.5-5x faster on these small layers) once that agrees with cv::dnn on probe crops when the file is
// loaded (a disagreement is an error, never a silent answer), and by cv::dnn for a graph of another form or with
// cascade.verifier_dnn.
//
// Trained by `headway train verifier --out X.onnx` (app/train/verifier_cnn.py, JAX) and written as ONNX
// (app/train/verifier_onnx.py, which also holds the network's equations). Its inputs, computed here exactly
// as the trainer computes them:
// - crop (N, 1, kCropH, kCropW): the box widened by kMargin (or the file's margin) of its size each side, rounded to whole pixels
//   (floor(v + 0.5)), the part outside the image filled by replicating the border, resized to kCropW x kCropH
//   (INTER_AREA), standardised by its own mean and standard deviation, z = (c - mean) / (std + 1);
// - extra (N, 2): log(1 + n) of the n raw cascade windows grouped, and implied_vehicle_height.
// Outputs: p (N, 1), the probability that the box holds a vehicle, and, in a network trained with it,
// box (N, 4): offsets d that move the box's edges onto the vehicle's,
//     l' = l + d0 w,   t' = t + d1 h,   r' = r + d2 w,   b' = b + d3 h    (w, h: the box's width and height)
// (verifier_onnx.refine), with margin (N, 1): the crop margin it was trained with, a constant read once by the
// probe (it replaces kMargin for that file). All the boxes of a frame go through the network in one batch.
//
// Mirrored (cascade.verify_mirrored): the left-right mirror image of each crop the plain look gives at least
// mirror_min_p also goes through the network, and the two answers are averaged, p = (p + p_m) / 2, the offsets with
// the mirror's left and right swapped and negated, d = (d0 - dm2, d1 + dm1, d2 - dm0, d3 + dm3) / 2. A vehicle seen
// from behind is nearly symmetric and the network was trained on crops mirrored at random, so the two are two
// estimates of the same answer; their mean ranks the boxes better (docs/detection.md). A box below
// mirror_min_p keeps its plain answer: its mean could not reach (mirror_min_p + 1) / 2, so every score from there up
// is the one mirroring every box gives, for the cost of mirroring the few believed boxes.
#pragma once

#include "detect/vehicle_verifier.hpp"
#include "detect/verifier_net.hpp"

#include <opencv2/dnn.hpp>

namespace hw {

class CnnVerifier : public VehicleVerifier {
public:
    static constexpr int kCropW = 48, kCropH = 32;  // px: the cascade's aspect 1.5
    static constexpr int kChunk = 16;               // boxes per pass through cv::dnn (cache-sized)
    static constexpr double kMargin = 0.1;  // of the box's width (height) added each side: context (networks
                                            // with the box output carry their own: output "margin")

    // throws std::invalid_argument naming the file
    // `dnn`: cv::dnn runs the network (the reference) even where the own forward pass (verifier_net.hpp) could
    explicit CnnVerifier(const std::string &path, bool mirrored = false, double mirror_min_p = 0.0, bool dnn = false);
    std::vector<float> probabilities(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes,
                                     const std::vector<int> &neighbors, double horizon_row, double cam_height_m,
                                     const cv::Mat *integral = nullptr) const override;
    void set_pool(WorkerPool *pool) override;
    std::vector<float> judge(const cv::Mat &gray, std::vector<cv::Rect2f> &boxes, const std::vector<int> &neighbors,
                             double horizon_row, double cam_height_m, const cv::Mat *integral = nullptr) const override;
    bool has_box_output() const override { return has_box_; }
    cv::Mat integral_of(const cv::Mat &gray) const override;
    // The standardised crop of one box (kCropH x kCropW, float) widened by `margin` each side, as the network takes it;
    // with the image's integral (CV_32S) a crop inside the image and larger than kCropW x kCropH is averaged from it.
    static cv::Mat crop(const cv::Mat &gray, const cv::Rect2f &box, double margin, const cv::Mat *integral = nullptr);
    // true when the network runs by its own forward pass (verifier_net.hpp) rather than cv::dnn
    bool own_forward() const { return own_ != nullptr; }

private:
    // p (n) and, with the box output, offsets (n x 4 float) for the boxes; `offsets` left empty without one
    std::vector<float> run(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes, const std::vector<int> &neighbors,
                           double horizon_row, double cam_height_m, cv::Mat *offsets, const cv::Mat *integral) const;
    // one batch through the network: the crops of boxes[which[k]] (cut with `integral`, gray's, made here when null),
    // or with `plain` (the crops of every box, as a batch without it gives in `crops_out`) those crops mirrored; p[k]
    // and offsets (row k)
    void batch(const cv::Mat &gray, const std::vector<cv::Rect2f> &boxes, const std::vector<int> &neighbors,
               const std::vector<int> &which, const cv::Mat *plain, const cv::Mat *integral, double horizon_row,
               double cam_height_m, float *p, cv::Mat *offsets, cv::Mat *crops_out) const;

    // the crops (n, 1, kCropH, kCropW) and extra features (n x 2) through the network: p[n], offsets (n x 4, allocated)
    // with the box output; by the own forward pass unless `dnn` or there is none
    void forward(const cv::Mat &crops, const cv::Mat &extra, float *p, cv::Mat *offsets, bool dnn = false) const;
    // the largest difference between the own forward pass (plain and, where the CPU has it, AVX2) and cv::dnn on a few
    // random crops, over the probabilities and the box offsets
    double own_disagreement() const;

    std::unique_ptr<VerifierNet> own_;  // null: cv::dnn runs the network
    WorkerPool *pool_ = nullptr;         // the stage's threads: the crops are cut on them too
    mutable cv::dnn::Net net_;  // forward() is not const; one verifier serves one pipeline thread
    bool has_box_ = false;      // the file has the box output ("box", N x 4)
    bool mirrored_ = false;     // crops the plain look believes judged with their mirror image, answers averaged
    double mirror_min_p_ = 0.0; // the plain look's probability from which a crop's mirror image is judged too
    double margin_ = kMargin;   // of the box's size added each side of the crop: the file's "margin" output, if any
    std::vector<cv::String> outs_;  // output names asked of forward(): {"p"} or {"p", "box"}
};

} // namespace hw
