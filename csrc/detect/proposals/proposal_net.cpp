#include "detect/proposals/proposal_net.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

ProposalNet::ProposalNet(const std::string &path, const std::string &key) {
    const std::string how = "; train one with `headway train proposals --out X.onnx` or leave the key empty (the shipped model)";
    try {
        net_ = cv::dnn::readNetFromONNX(path);
    } catch (const cv::Exception &e) {
        throw std::invalid_argument(key + ": cv::dnn cannot read '" + path + "' as ONNX (" + e.err + ")" + how);
    }
    if (net_.empty()) throw std::invalid_argument(key + ": '" + path + "' holds no network" + how);
    net_.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    net_.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
    std::vector<cv::String> names = net_.getUnconnectedOutLayersNames();
    std::sort(names.begin(), names.end());
    if (names != std::vector<cv::String>{"box", "heat"}) {
        std::string got;
        for (const auto &n : names) got += (got.empty() ? "" : ", ") + n;
        throw std::invalid_argument(key + ": '" + path + "' is not a proposal network (outputs heat and box; it has " +
                                    got + ")" + how);
    }
    try {  // one probe: a grey image must give maps of the grid's size
        const cv::Mat probe(64, 64, CV_8UC1, cv::Scalar(128));
        peaks(probe, 64, 2.f, 1);
    } catch (const std::exception &e) {
        throw std::invalid_argument(key + ": '" + path + "' does not run as a proposal network (" + e.what() + ")" + how);
    }
}

cv::Size ProposalNet::input_size(cv::Size size, int input_width) {
    const int h = int(std::floor(double(size.height) * input_width / size.width + 0.5));
    return {input_width, std::max(8, h)};
}

std::vector<ProposalPeak> ProposalNet::peaks(const cv::Mat &gray, int input_width, float min_heat, int top_k) const {
    CV_Assert(gray.type() == CV_8UC1 && !gray.empty());
    const cv::Size in = input_size(gray.size(), input_width);
    cv::Mat small;
    cv::resize(gray, small, in, 0, 0, cv::INTER_AREA);
    net_.setInput(cv::dnn::blobFromImage(small, 1.0 / kScale, cv::Size(), cv::Scalar(kMean)), "image");
    std::vector<cv::Mat> outs;
    net_.forward(outs, std::vector<cv::String>{"heat", "box"});
    const cv::Mat &hb = outs[0], &bb = outs[1];
    // the last level's stride, 4 or 8, from the maps' size (each stride-2 layer rounds up), and the sub-cells a side
    // of each of its cells from the heat's channels (1 or 4)
    int stride = 0, oh = in.height, ow = in.width;
    for (int s = 2; s <= 8 && !stride; s *= 2) {
        oh = (oh + 1) / 2;
        ow = (ow + 1) / 2;
        if (s >= 4 && hb.dims == 4 && hb.size[2] == oh && hb.size[3] == ow) stride = s;
    }
    const int sub = stride && hb.size[1] == 4 ? 2 : 1;
    if (!stride || hb.size[1] != sub * sub || bb.dims != 4 || bb.size[1] != 4 * sub * sub || bb.size[2] != oh ||
        bb.size[3] != ow)
        throw std::runtime_error("its outputs are not heat (1, s*s, h, w) and box (1, 4*s*s, h, w) of stride 4 or 8, "
                                 "s = 1 or 2");
    // the grid: sub-cell (di, dj) of cell (i, j) at row sub i + di, column sub j + dj (heat channel sub di + dj, box
    // channel sub^2 k + sub di + dj for edge k; app/train/proposals_onnx.py)
    const int gh = sub * oh, gw = sub * ow;
    const float cell = float(stride) / sub;
    cv::Mat heat(gh, gw, CV_32F), box(4 * gh, gw, CV_32F);
    {
        const size_t plane = size_t(oh) * ow;
        const float *h = hb.ptr<float>(), *b = bb.ptr<float>();
        for (int di = 0; di < sub; ++di)
            for (int dj = 0; dj < sub; ++dj)
                for (int i = 0; i < oh; ++i)
                    for (int j = 0; j < ow; ++j) {
                        const size_t at = size_t(i) * ow + j, c = size_t(sub * di + dj);
                        heat.at<float>(sub * i + di, sub * j + dj) = h[c * plane + at];
                        for (int k = 0; k < 4; ++k)
                            box.at<float>(k * gh + sub * i + di, sub * j + dj) = b[(size_t(k) * sub * sub + c) * plane + at];
                    }
    }
    cv::Mat local_max;
    cv::dilate(heat, local_max, cv::Mat::ones(3, 3, CV_8U));
    struct Cell { float v; int i, j; };
    std::vector<Cell> cells;
    for (int i = 0; i < gh; ++i) {
        const float *h = heat.ptr<float>(i), *m = local_max.ptr<float>(i);
        for (int j = 0; j < gw; ++j)
            if (h[j] >= min_heat && h[j] >= m[j]) cells.push_back({h[j], i, j});
    }
    // strongest first; ties in the grid's order (as the trainer's stable sort)
    std::stable_sort(cells.begin(), cells.end(), [](const Cell &a, const Cell &b) { return a.v > b.v; });
    if (int(cells.size()) > top_k) cells.resize(size_t(std::max(0, top_k)));
    const float sx = float(gray.cols) / in.width, sy = float(gray.rows) / in.height;
    const float *b = box.ptr<float>();
    const size_t plane = size_t(gh) * gw;
    std::vector<ProposalPeak> out;
    for (const Cell &c : cells) {
        const size_t at = size_t(c.i) * gw + c.j;
        const float xc = cell * c.j + 0.5f, yc = cell * c.i + 0.5f;
        const float l = xc - std::exp(b[at]) * cell, t = yc - std::exp(b[plane + at]) * cell;
        const float r = xc + std::exp(b[2 * plane + at]) * cell, bo = yc + std::exp(b[3 * plane + at]) * cell;
        out.push_back({cv::Rect2f(l * sx, t * sy, (r - l) * sx, (bo - t) * sy), c.v});
    }
    return out;
}

} // namespace hw
