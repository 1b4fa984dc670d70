#include "track/birth_gate.hpp"

#include "base/types.hpp"

#include <algorithm>
#include <cmath>

namespace hw {

bool on_tracked_vehicle(const cv::Rect2f &b, const std::vector<cv::Rect2f> &tracked, const BirthGateParams &p) {
    const cv::Point2f foot(b.x + 0.5f * b.width, b.y + b.height);
    for (const cv::Rect2f &tb : tracked) {
        if (p.nearer_below > 0.0 && foot.y - (tb.y + tb.height) > p.nearer_below * tb.height && b.x <= tb.x &&
            b.x + b.width >= tb.x + tb.width)
            continue;
        if (box_iou(tb, b) >= float(p.explained_iou)) return true;
        if (foot.x >= tb.x && foot.x <= tb.x + tb.width && foot.y >= tb.y && foot.y <= tb.y + tb.height) return true;
        if (p.beside_overlap >= 1.0) continue;
        const float narrower = std::min(tb.width, b.width);
        const float overlap = std::min(tb.x + tb.width, b.x + b.width) - std::max(tb.x, b.x);
        if (std::abs(tb.y + tb.height - foot.y) <= p.beside_bottom_tol * narrower &&
            overlap >= p.beside_overlap * narrower)
            return true;
    }
    return false;
}

} // namespace hw
