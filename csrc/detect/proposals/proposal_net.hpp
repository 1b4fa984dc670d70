// proposal_net.hpp - the learned first stage's network: where the vehicles are in one image.
//
// A small fully convolutional network (`headway train proposals`, app/train/proposals.py; its layers and decoding in
// app/train/proposals_onnx.py) read from ONNX and run by cv::dnn. Input: the gray image resized to `input_width` x
// round(rows * input_width / cols) by the pixel-area mean (INTER_AREA), z = (g - 127.5) / 64. Outputs of the last
// level, of stride 8 (or 4 for a network without the third level; read from the maps' size), each cell carrying s x s
// sub-cells (s = 1 or 2, from the channels): "heat" (1, s^2, h, w), each sub-cell's objectness (a vehicle's centre is
// a peak), and "box" (1, 4 s^2, h, w), log(distance / S) from the sub-cell's centre (S j + 0.5, S i + 0.5 on the
// grid of stride S = the level's over s) to the box's left, top, right and bottom edges.
// Decoding: a cell is a peak when its heat is the largest of its 3x3 neighbourhood and at least min_heat; the
// strongest top_k peaks are kept, each with its box scaled back to the image.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

#include <string>
#include <vector>

namespace hw {

struct ProposalPeak {
    cv::Rect2f box;   // px of the image, as annotations draw the vehicle (not cut to the image)
    float heat = 0.f; // the peak's objectness, 0..1
};

class ProposalNet {
public:
    static constexpr double kMean = 127.5, kScale = 64.0;

    // throws std::invalid_argument naming `key` (the configuration key that gave the path) and the file
    ProposalNet(const std::string &path, const std::string &key);
    // The peaks of a gray image (CV_8UC1), strongest first.
    std::vector<ProposalPeak> peaks(const cv::Mat &gray, int input_width, float min_heat, int top_k) const;
    // The network's input size for an image of `size`: input_width wide, the aspect kept.
    static cv::Size input_size(cv::Size size, int input_width);

private:
    mutable cv::dnn::Net net_;  // forward() is not const; one part serves one pipeline thread
};

} // namespace hw
