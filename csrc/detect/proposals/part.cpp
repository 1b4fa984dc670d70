#include "detect/proposals/part.hpp"

#include "base/part_registry.hpp"
#include "base/stopwatch.hpp"
#include "cues/road_prior.hpp"
#include "detect/vehicle_verifier.hpp"

#include <algorithm>
#include <stdexcept>

namespace hw {

namespace {

ProposalsParams checked(const ProposalsParams &p) {
    if (p.model.empty())
        throw std::invalid_argument("proposals.model: no proposal network given (Headway's Python side fills in the shipped one)");
    if (p.max_vehicle_height_m <= p.min_vehicle_height_m)
        throw std::invalid_argument("proposals.max_vehicle_height_m must exceed proposals.min_vehicle_height_m");
    if (p.max_width_ratio <= p.min_width_ratio)
        throw std::invalid_argument("proposals.max_width_ratio must exceed proposals.min_width_ratio");
    return p;
}

// A hypothesis of this part: its score is also its appearance (a learned score), the peak's heat its strength.
Hypothesis proposal(const cv::Rect2f &box, float score, float heat) {
    Hypothesis h = hypothesis_of(box, score, heat, "proposals");
    h.appearance = score;
    return h;
}

} // namespace

ProposalsDetector::ProposalsDetector(const ProposalsParams &p) : p_(checked(p)), net_(p_.model, "proposals.model") {
    if (p_.verifier.empty())
        throw std::invalid_argument("proposals.verifier: no verifier given (Headway's Python side fills in the shipped "
                                    "one); set it to off for none");
    if (p_.verifier != "off") {
        try {
            verifier_ = make_vehicle_verifier(p_.verifier, p_.verify_mirrored, 0.5);
        } catch (const std::invalid_argument &e) {
            throw std::invalid_argument(std::string("proposals.verifier: ") + e.what());
        }
    }
}

ProposalsDetector::~ProposalsDetector() = default;

bool ProposalsDetector::detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) {
    Stopwatch sw;
    const cv::Mat &gray = ctx.gray;
    const cv::Rect2f image(0.f, 0.f, float(gray.cols), float(gray.rows));
    const double yh = horizon_row(gray.size(), ctx.lanes, ctx.camera), hc = ctx.camera.height_m;
    RoadPriorParams prior;
    prior.road = p_.road;
    prior.shape = p_.shape;
    const auto below_horizon = [&](const cv::Rect2f &box) { return box.br().y > yh + 1.0; };
    // A box standing on the road: the vehicle height it implies and its width against the row's expected one.
    const auto on_road = [&](const cv::Rect2f &box) {
        if (!below_horizon(box)) return false;
        const float yb = box.br().y;
        const double implied = implied_vehicle_height(box, yh, hc);
        if (implied < p_.min_vehicle_height_m || implied > p_.max_vehicle_height_m) return false;
        const double ratio = box.width / std::max(1e-3f, expected_vehicle_width(yb, gray.size(), ctx.lanes, ctx.camera, prior));
        const bool cut = box.x <= 0.5f || box.br().x >= image.width - 0.5f;
        return ratio <= p_.max_width_ratio && (cut || ratio >= p_.min_width_ratio);
    };
    // The verifier's box output moves each candidate onto its vehicle; the network's own boxes are coarser (stride
    // 8), so with that output the size checks judge the moved box, and before it only "standing below the horizon".
    const bool moves = verifier_ && p_.refine_boxes;
    // every peak (top_k counts the candidates that pass the checks made before the verifier)
    std::vector<Hypothesis> cand;
    for (const ProposalPeak &pk : net_.peaks(gray, p_.input_width, float(p_.min_heat), 4 * p_.top_k)) {
        const cv::Rect2f box = pk.box & image;
        if (box.width < 2.f || box.height < 2.f) continue;
        if (!(moves ? below_horizon(box) : on_road(box))) continue;
        cand.push_back(proposal(box, pk.heat, pk.heat));
        if (int(cand.size()) >= p_.top_k) break;
    }
    times.add("proposals", sw.ms());
    if (verifier_ && !cand.empty()) {
        Stopwatch sv;
        std::vector<cv::Rect2f> boxes;
        for (const Hypothesis &h : cand) boxes.push_back(h.box);
        const std::vector<int> n(boxes.size(), p_.verifier_windows);
        const double yc = ctx.camera.horizon_row();  // the horizon the cascade hands the verifier
        const cv::Mat ii = verifier_->integral_of(gray);  // once for every look
        const cv::Mat *integral = ii.empty() ? nullptr : &ii;
        std::vector<float> p = p_.refine_boxes ? verifier_->judge(gray, boxes, n, yc, hc, integral)
                                               : verifier_->probabilities(gray, boxes, n, yc, hc, integral);
        for (int look = 1; p_.refine_boxes && look < p_.refine_looks; ++look) {
            for (auto &b : boxes) b &= image;
            const std::vector<float> again = verifier_->judge(gray, boxes, n, yc, hc, integral);
            for (size_t k = 0; k < p.size(); ++k) p[k] = std::min(p[k], again[k]);
        }
        std::vector<Hypothesis> judged;
        for (size_t k = 0; k < cand.size(); ++k) {
            const cv::Rect2f moved = boxes[k] & image;  // the box output's, in the image (unmoved without one)
            const cv::Rect2f box = moved.width >= 2.f && moved.height >= 2.f ? moved : cand[k].box;
            if (!moves || on_road(box)) judged.push_back(proposal(box, p[k], cand[k].strength));
        }
        cand.swap(judged);
        times.add("prop_verifier", sv.ms());
    }
    // most confident first; a candidate overlapping a kept one at nms_iou is a second look at the same vehicle
    std::stable_sort(cand.begin(), cand.end(), [](const Hypothesis &a, const Hypothesis &b) { return a.score > b.score; });
    const size_t first = out.size();
    for (const Hypothesis &h : cand) {
        bool dup = false;
        for (size_t k = first; k < out.size() && !dup; ++k) dup = box_iou(h.box, out[k].box) >= p_.nms_iou;
        if (!dup) out.push_back(h);
    }
    return true;
}

namespace {

// The part, its configuration section and its factory (base/part_registry.hpp).
const bool registered = register_part<Detector, ProposalsParams>(
    "proposals", "proposals",
    [](const ProposalsParams &p, const SectionLookup &) { return std::make_unique<ProposalsDetector>(p); });

} // namespace

} // namespace hw
