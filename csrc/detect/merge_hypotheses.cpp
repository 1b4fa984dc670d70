#include "detect/merge_hypotheses.hpp"

#include "base/stopwatch.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace hw {

namespace {

float bottom_of(const cv::Rect2f &b) { return b.y + b.height; }

// Anchor rank: a measured shadow edge gives the most precise bottom row, then a learned box, then any.
int rank(const Hypothesis &h) { return std::isfinite(h.road_gray) ? 0 : std::isfinite(h.appearance) ? 1 : 2; }

bool same_vehicle(const Hypothesis &a, const Hypothesis &b, const MergeParams &p) {
    const float w = std::max(a.box.width, b.box.width);
    if (std::abs(bottom_of(a.box) - bottom_of(b.box)) > float(p.bottom_tol) * w) return false;
    const float inter = std::min(a.box.x + a.box.width, b.box.x + b.box.width) - std::max(a.box.x, b.box.x);
    const float uni = std::max(a.box.x + a.box.width, b.box.x + b.box.width) - std::min(a.box.x, b.box.x);
    return inter > 0.f && uni > 0.f && inter / uni >= float(p.span_iou);
}

// Mean gray level of the road just under a bottom edge (rows +2 .. +2 + 0.15 widths, as the verification's
// texture strip); NaN when that strip leaves the image.
float road_gray_below(const cv::Mat &gray, const cv::Rect2f &b) {
    cv::Rect strip(int(std::lround(b.x)), int(std::lround(bottom_of(b))) + 2, int(std::lround(b.width)),
                   std::max(3, int(0.15f * b.width)));
    strip &= cv::Rect(0, 0, gray.cols, gray.rows);
    if (strip.width < 3 || strip.height < 1) return kNaN;
    return float(cv::mean(gray(strip))[0]);
}

// Whether a bottom centre (u, y) lies on the ego lane or within `lanes_beside` lane widths of it; true when
// the lane model does not say.
bool near_ego_lane(const LaneModel &lanes, float u, float y, int lanes_beside) {
    const float l = lanes.ego_left.x_at(y), r = lanes.ego_right.x_at(y);
    if (!lanes.valid || !std::isfinite(l) || !std::isfinite(r) || !(r > l)) return true;
    const float w = r - l;
    return u >= l - float(lanes_beside) * w && u <= r + float(lanes_beside) * w;
}

struct Group {
    Hypothesis anchor;
    std::vector<const char *> sources;  // the detectors of its members, each once
    float appearance = 0.f;  // best appearance score among the members (0: none)

    bool has(const char *source) const {
        for (const char *s : sources)
            if (std::strcmp(s, source) == 0) return true;
        return false;
    }
};

} // namespace

std::vector<Hypothesis> HypothesisMerge::merge_and_verify(const RoadContext &ctx,
                                                          const std::vector<Hypothesis> &raw) const {
    std::vector<Hypothesis> order(raw);
    std::stable_sort(order.begin(), order.end(), [](const Hypothesis &a, const Hypothesis &b) {
        return rank(a) != rank(b) ? rank(a) < rank(b) : a.score > b.score;
    });
    std::vector<Group> groups;
    for (const Hypothesis &h : order) {
        // One hypothesis per detector in a vehicle: two of one detector stay apart, each verified (as the
        // shadow detector alone does), the overlap thinned after.
        Group *g = nullptr;
        for (auto &k : groups)
            if (!g && !k.has(h.source) && same_vehicle(k.anchor, h, p_)) g = &k;
        if (!g) {
            groups.push_back({h, {}, 0.f});
            g = &groups.back();
        }
        g->sources.push_back(h.source);
        if (std::isfinite(h.appearance)) g->appearance = std::max(g->appearance, h.appearance);
    }

    std::vector<Detection> found;
    std::vector<const char *> source;
    for (const Group &g : groups) {
        const bool shadow_edge = std::isfinite(g.anchor.road_gray);
        const bool appearance_only = !shadow_edge && g.sources.size() < 2;
        // min_appearance 1: never (a network's probability can round to 1.0f)
        if (appearance_only && (p_.min_appearance >= 1.0 || g.appearance < float(p_.min_appearance))) continue;
        const cv::Rect2f &b = g.anchor.box;
        const float bottom = bottom_of(b);
        if (appearance_only && !near_ego_lane(ctx.lanes, b.x + 0.5f * b.width, bottom, p_.appearance_lanes)) continue;
        // The anchor as the verification's bottom edge (its box's height is not used).
        ShadowHypothesis s;
        s.box = cv::Rect2f(b.x, bottom - 0.5f * b.width, b.width, 0.5f * b.width);
        s.expected_width_px = expected_vehicle_width(bottom, ctx.gray.size(), ctx.lanes, ctx.camera, road_);
        s.road_gray = shadow_edge ? g.anchor.road_gray : road_gray_below(ctx.gray, b);
        s.strength = shadow_edge ? g.anchor.strength : 0.f;  // the shadow's depth
        if (!std::isfinite(s.road_gray)) continue;
        Detection d;
        if (!verify_one(ctx.gray, s, verify_, d)) continue;
        d.score = 1.f - (1.f - d.score) * (1.f - float(p_.appearance_weight) * g.appearance);
        found.push_back(d);
        source.push_back(g.anchor.source);
    }
    // Thinned as the shadow detector does; each kept detection keeps its anchor's source name.
    std::vector<Hypothesis> out;
    for (size_t i : strongest_apart(found, verify_.nms_iou)) out.push_back(hypothesis_of(found[i], source[i]));
    return out;
}

bool DetectorSet::detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) {
    bool any = false;
    if (!merge) {
        for (auto &d : parts) any = d->detect(ctx, out, times) || any;
        return any;
    }
    std::vector<Hypothesis> raw;
    for (auto &d : parts) any = d->unverified(ctx, raw, times) || any;
    Stopwatch sw;
    const auto merged = merge->merge_and_verify(ctx, raw);
    times.add("merge", sw.ms());
    out.insert(out.end(), merged.begin(), merged.end());
    return any;
}

} // namespace hw
