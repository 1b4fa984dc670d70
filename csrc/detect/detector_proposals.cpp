#include "detect/detector_proposals.hpp"

#include "base/stopwatch.hpp"
#include "detect/road_prior.hpp"
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
    // every peak (top_k counts the candidates that pass the road checks)
    std::vector<Hypothesis> cand;
    for (const ProposalPeak &pk : net_.peaks(gray, p_.input_width, float(p_.min_heat), 4 * p_.top_k)) {
        const cv::Rect2f box = pk.box & image;
        if (box.width < 2.f || box.height < 2.f) continue;
        const float yb = box.br().y;
        if (yb <= yh + 1.0) continue;
        const double implied = implied_vehicle_height(box, yh, hc);
        if (implied < p_.min_vehicle_height_m || implied > p_.max_vehicle_height_m) continue;
        const double ratio = box.width / std::max(1e-3f, expected_vehicle_width(yb, gray.size(), ctx.lanes, ctx.camera, prior));
        const bool cut = box.x <= 0.5f || box.br().x >= image.width - 0.5f;
        if (ratio > p_.max_width_ratio || (!cut && ratio < p_.min_width_ratio)) continue;
        Hypothesis h = hypothesis_of(box, pk.heat, pk.heat, "proposals");
        h.appearance = pk.heat;
        cand.push_back(h);
        if (int(cand.size()) >= p_.top_k) break;
    }
    times.add("proposals", sw.ms());
    if (verifier_ && !cand.empty()) {
        Stopwatch sv;
        std::vector<cv::Rect2f> boxes;
        for (const Hypothesis &h : cand) boxes.push_back(h.box);
        const std::vector<float> p =
            verifier_->probabilities(gray, boxes, std::vector<int>(boxes.size(), p_.verifier_windows),
                                     ctx.camera.horizon_row(), hc);  // the horizon the cascade hands it
        for (size_t k = 0; k < cand.size(); ++k) cand[k].score = cand[k].appearance = p[k];
        times.add("proposals_verifier", sv.ms());
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

} // namespace hw
