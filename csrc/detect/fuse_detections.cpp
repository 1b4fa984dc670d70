#include "detect/fuse_detections.hpp"

#include <algorithm>

namespace hw {

namespace {
float box_iou(const cv::Rect2f &a, const cv::Rect2f &b) {
    const float inter = (a & b).area();
    return inter <= 0 ? 0.f : inter / (a.area() + b.area() - inter);
}
} // namespace

std::vector<Detection> fuse_detections(const std::vector<CascadeDetection> &cascade,
                                       const std::vector<Detection> &shadow, const FuseParams &p) {
    std::vector<Detection> out;
    std::vector<char> taken(shadow.size(), 0);
    for (const auto &c : cascade) {
        int best = -1;
        float best_iou = float(p.match_iou);
        for (size_t j = 0; j < shadow.size(); ++j) {
            const float v = box_iou(c.box, shadow[j].box);
            if (!taken[j] && v >= best_iou) { best = int(j); best_iou = v; }
        }
        Detection d{c.box, c.confidence};
        if (best >= 0) {
            taken[size_t(best)] = 1;
            d.score = std::min(1.f, std::max(c.confidence, shadow[size_t(best)].score) + float(p.agree_bonus));
        }
        out.push_back(d);
    }
    for (size_t j = 0; j < shadow.size(); ++j)
        if (!taken[j]) out.push_back({shadow[j].box, float(p.thesis_weight) * shadow[j].score});
    std::sort(out.begin(), out.end(), [](const Detection &a, const Detection &b) { return a.score > b.score; });
    return out;
}

} // namespace hw
