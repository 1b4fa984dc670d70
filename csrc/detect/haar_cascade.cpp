#include "detect/haar_cascade.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace hw {

namespace {

const float kThresholdEps = 1e-5f;  // OpenCV lowers every stage threshold by this when it reads the XML

[[noreturn]] void bad(const std::string &path, const std::string &why) {
    throw std::invalid_argument("cascade.model: '" + path + "' " + why +
                                "; train one with `headway train cascade` or leave the key empty");
}

std::vector<float> numbers(const cv::FileNode &n) {
    std::vector<float> v;
    if (n.isSeq())
        for (const auto &e : n) v.push_back(float(double(e)));
    else if (n.isString()) {  // "0 -1 373 -0.032" written as one string by some writers
        std::istringstream is{std::string(n)};
        for (double d; is >> d;) v.push_back(float(d));
    } else if (n.isReal() || n.isInt())
        v.push_back(float(double(n)));
    return v;
}

} // namespace

HaarCascade::HaarCascade(const std::string &path) {
    cv::FileStorage fs;
    try {
        fs.open(path, cv::FileStorage::READ);
    } catch (const cv::Exception &e) {
        bad(path, std::string("cannot be parsed (") + e.what() + ")");
    }
    if (!fs.isOpened()) bad(path, "cannot be opened");
    const cv::FileNode root = fs.getFirstTopLevelNode();
    if (std::string(root["stageType"]) != "BOOST" || std::string(root["featureType"]) != "HAAR")
        bad(path, "is not an OpenCV cascade with stageType BOOST and featureType HAAR (new format)");
    win_ = cv::Size(int(root["width"]), int(root["height"]));
    if (win_.width < 3 || win_.height < 3) bad(path, "has no window size");
    for (const auto &fn : root["features"]) {
        if (!fn["tilted"].empty() && int(fn["tilted"]) != 0) bad(path, "has tilted features (not supported)");
        Feature f{};
        for (const auto &rn : fn["rects"]) {
            const std::vector<float> v = numbers(rn);
            if (v.size() != 5 || f.n >= 3) bad(path, "has a feature rectangle that is not x y w h weight");
            f.r[f.n++] = {int(v[0]), int(v[1]), int(v[2]), int(v[3]), v[4]};
        }
        if (f.n < 2) bad(path, "has a feature with fewer than two rectangles");
        features_.push_back(f);
    }
    for (const auto &sn : root["stages"]) {
        Stage st{int(stumps_.size()), 0, float(double(sn["stageThreshold"])) - kThresholdEps};
        for (const auto &wn : sn["weakClassifiers"]) {
            const std::vector<float> in = numbers(wn["internalNodes"]), leaves = numbers(wn["leafValues"]);
            if (in.size() != 4 || leaves.size() != 2) bad(path, "has a weak classifier that is not a stump");
            const int fi = int(in[2]);
            if (fi < 0 || fi >= int(features_.size())) bad(path, "refers to a feature it does not define");
            stumps_.push_back({fi, in[3], leaves[0], leaves[1]});
            ++st.count;
        }
        if (st.count == 0) bad(path, "has a stage without weak classifiers");
        stages_.push_back(st);
    }
    if (stages_.empty()) bad(path, "has no stages");
}

void HaarCascade::layout(int step) const {
    if (step == laid_step_) return;
    // corner offsets of rectangle (x, y, w, h): p0 = (x, y), p1 = (x + w, y), p2 = (x, y + h), p3 = (x + w, y + h)
    auto corners = [step](int x, int y, int w, int h, int *o) {
        o[0] = y * step + x; o[1] = y * step + x + w; o[2] = (y + h) * step + x; o[3] = (y + h) * step + x + w;
    };
    nodes_.resize(stumps_.size());
    for (size_t i = 0; i < stumps_.size(); ++i) {
        const Feature &f = features_[size_t(stumps_[i].feature)];
        Node &n = nodes_[i];
        for (int k = 0; k < 3; ++k) {
            const Rect r = k < f.n ? f.r[k] : Rect{0, 0, 0, 0, 0.f};
            corners(r.x, r.y, r.w, r.h, n.ofs[k]);
            n.w[k] = r.weight;
        }
        n.threshold = stumps_[i].threshold;
        n.left = stumps_[i].left;
        n.right = stumps_[i].right;
    }
    corners(1, 1, win_.width - 2, win_.height - 2, norm_ofs_);  // OpenCV's normrect
    laid_step_ = step;
}

// OpenCV's runAt for one window: 1 = accepted by every stage, -s = rejected by stage s (0 for the first),
// -1 = not classified (flat window). `sum`, `sq`: the integrals at the window's top-left corner.
int HaarCascade::classify(const int *sum, const unsigned *sq, double &stage_sum) const {
    const int *o = norm_ofs_;
    const int valsum = sum[o[0]] - sum[o[1]] - sum[o[2]] + sum[o[3]];
    const unsigned valsq = sq[o[0]] - sq[o[1]] - sq[o[2]] + sq[o[3]];
    const double area = double(win_.width - 2) * (win_.height - 2);
    double nf = area * valsq - double(valsum) * valsum;
    if (!(nf > 0.)) return -1;
    nf = std::sqrt(nf);
    const float norm = float(1. / nf);
    if (!(area * norm < 1e-1)) return -1;
    const Node *node = nodes_.data();
    double t = 0;
    for (size_t s = 0; s < stages_.size(); ++s) {
        const Stage &st = stages_[s];
        t = 0;
        for (const Node *end = node + st.count; node != end; ++node) {
            const int *a = node->ofs[0], *b = node->ofs[1];
            float r = node->w[0] * float(sum[a[0]] - sum[a[1]] - sum[a[2]] + sum[a[3]]) +
                      node->w[1] * float(sum[b[0]] - sum[b[1]] - sum[b[2]] + sum[b[3]]);
            if (node->w[2] != 0.f) {
                const int *c = node->ofs[2];
                r += node->w[2] * float(sum[c[0]] - sum[c[1]] - sum[c[2]] + sum[c[3]]);
            }
            const double v = r * norm;
            t += v < node->threshold ? node->left : node->right;
        }
        if (t < st.threshold) {
            stage_sum = t;
            return -int(s);
        }
    }
    stage_sum = t;
    return 1;
}

void HaarCascade::scan(const cv::Mat &img, int step, std::vector<HaarWindow> &out) const {
    CV_Assert(img.type() == CV_8UC1 && step >= 1);
    if (img.cols <= win_.width || img.rows <= win_.height) return;
    cv::integral(img, sum_, sqsum_, CV_32S, CV_32S);
    CV_Assert(sum_.isContinuous() && sqsum_.isContinuous() && sum_.step == sqsum_.step);
    layout(sum_.cols);
    // OpenCV's rows: its working size is (cols + 1 - W, rows + 1 - H), cut into ceil(width / 32) stripes of whole
    // steps, ((height / step + stripes - 1) / stripes) steps each (integer division): the last row of the working
    // size is left out when the stripes do not reach it. Reproduced so that step 2 scans OpenCV's windows.
    const int ww = img.cols + 1 - win_.width, wh = img.rows + 1 - win_.height;
    const int stripes = (ww + 31) / 32, stripe = std::max((wh / step + stripes - 1) / stripes, 1) * step;
    const int yend = std::min(stripes * stripe, wh);
    for (int y = 0; y < yend; y += step) {
        const int *srow = sum_.ptr<int>(y);
        const unsigned *qrow = sqsum_.ptr<unsigned>(y);
        for (int x = 0; x < ww; x += step) {
            double s = 0;
            const int r = classify(srow + x, qrow + x, s);
            if (r == 1) out.push_back({x, y, s});
            else if (r == 0) x += step;  // OpenCV: the next window after a first-stage rejection is skipped
        }
    }
}

} // namespace hw
