#include "detect/fuse_hypotheses.hpp"

#include "base/stopwatch.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace hw {

namespace {

bool learned(const Hypothesis &h) { return std::isfinite(h.appearance); }

// The best-overlapping hypothesis of `cues` not yet taken, at IoU >= min_iou; -1 when none.
int best_match(const cv::Rect2f &box, const std::vector<const Hypothesis *> &cues, const std::vector<char> &taken,
               float min_iou) {
    int best = -1;
    float best_iou = min_iou;
    for (size_t j = 0; j < cues.size(); ++j) {
        const float v = box_iou(box, cues[j]->box);
        if (!taken[j] && v >= best_iou) { best = int(j); best_iou = v; }
    }
    return best;
}

// Whether `inner` lies within `outer`: at least 90 % of its area inside.
bool holds(const cv::Rect2f &outer, const cv::Rect2f &inner) { return (outer & inner).area() >= 0.9f * inner.area(); }

// The largest shadow cue not yet taken that `box` holds; -1 when none.
int held_shadow(const cv::Rect2f &box, const std::vector<const Hypothesis *> &cues, const std::vector<char> &taken) {
    int best = -1;
    float best_area = 0.f;
    for (size_t j = 0; j < cues.size(); ++j) {
        const float area = cues[j]->box.area();
        if (taken[j] || std::strcmp(cues[j]->source, "shadow") != 0 || area <= best_area) continue;
        if (holds(box, cues[j]->box)) { best = int(j); best_area = area; }
    }
    return best;
}

} // namespace

std::vector<Hypothesis> fuse_hypotheses(const std::vector<Hypothesis> &found, const FuseParams &p) {
    std::vector<const Hypothesis *> primary, cues;
    for (const Hypothesis &h : found) (learned(h) ? primary : cues).push_back(&h);
    std::stable_sort(primary.begin(), primary.end(), [](const Hypothesis *a, const Hypothesis *b) { return a->score > b->score; });
    const float bonus = float(p.agree_bonus);
    std::vector<Hypothesis> out;
    std::vector<char> taken(cues.size(), 0);
    for (const Hypothesis *c : primary) {
        // Two learned parts on one vehicle: the stronger one's box, the agreement bonus (each part has suppressed
        // its own overlapping detections already).
        Hypothesis *same = nullptr;
        for (size_t k = 0; k < out.size() && !same; ++k)
            if (std::strcmp(out[k].source, c->source) != 0 && box_iou(out[k].box, c->box) >= float(p.match_iou))
                same = &out[k];
        if (same) {
            same->score = std::min(1.f, same->score + bonus);
            continue;
        }
        Hypothesis v = *c;
        // a box lower than small_box_px takes the box of a shadow cue it holds (the cue confirming it, or else the
        // largest it holds): the cascade's smallest window is larger than a far car
        const bool small = c->box.height < float(p.small_box_px);
        int j = best_match(c->box, cues, taken, float(p.match_iou));
        if (small && j < 0) j = held_shadow(c->box, cues, taken);
        if (j >= 0) {
            const Hypothesis &cue = *cues[size_t(j)];
            taken[size_t(j)] = 1;
            v.score = std::min(1.f, std::max(c->score, cue.score) + bonus);
            const bool shadow = std::strcmp(cue.source, "shadow") == 0;
            if (small && shadow && holds(c->box, cue.box)) {
                v.box = cue.box;
                v.foot = cue.foot;
            } else if (p.shadow_bottom && shadow) {
                const float bottom = cue.box.y + cue.box.height;
                v.box.height = std::max(1.f, bottom - v.box.y);
                v.foot = {v.box.x + 0.5f * v.box.width, bottom};
            }
        }
        out.push_back(v);
    }
    // Cues no learned hypothesis explains; two parts' cues on one vehicle are one (the first part's box).
    const size_t learned_end = out.size();
    for (size_t j = 0; j < cues.size(); ++j) {
        if (taken[j]) continue;
        const Hypothesis &cue = *cues[j];
        Hypothesis *same = nullptr;
        for (size_t k = learned_end; k < out.size() && !same; ++k)
            if (std::strcmp(out[k].source, cue.source) != 0 && box_iou(out[k].box, cue.box) >= float(p.match_iou))
                same = &out[k];
        if (same) {
            same->score = std::min(1.f, same->score + bonus);
            continue;
        }
        Hypothesis v = cue;
        v.score = float(p.cue_weight) * cue.score;
        out.push_back(v);
    }
    std::stable_sort(out.begin(), out.end(), [](const Hypothesis &a, const Hypothesis &b) { return a.score > b.score; });
    return out;
}

bool DetectorSet::find(const RoadContext &ctx, std::vector<Hypothesis> &found, StageTimes &times) {
    bool any = false;
    for (auto &d : parts) any = d->detect(ctx, found, times) || any;
    if (parts.size() > 1) {
        Stopwatch sw;
        found = fuse_hypotheses(found, fuse);
        times.add("fuse", sw.ms());
    }
    return any;
}

bool DetectorSet::detect(const RoadContext &ctx, std::vector<Hypothesis> &out, StageTimes &times) {
    settle();  // the parts are the worker's while it runs
    std::vector<Hypothesis> found;
    const bool any = find(ctx, found, times);
    last = found;
    out.insert(out.end(), found.begin(), found.end());
    return any;
}

bool DetectorSet::can_start() const {
    return std::none_of(parts.begin(), parts.end(), [](const auto &d) { return d->needs_road_motion(); });
}

void DetectorSet::start(const RoadContext &ctx, int64_t frame_number) {
    if (!can_start())
        throw std::logic_error("DetectorSet::start: a detector part needs the road's motion; run detect() instead");
    if (!worker_) worker_ = std::make_unique<DetectionWorker>();
    worker_->wait();
    started_ = Started{ctx.gray.clone(), ctx.lanes, ctx.camera, ctx.t_s, frame_number};
    has_started_ = true;
    worker_->run([this] {
        Started &s = started_;
        const RoadContext c{s.gray, s.t_s, s.lanes, s.camera, nullptr};
        Stopwatch sw;
        const double cpu0 = thread_cpu_ms();
        s.ran = find(c, s.found, s.times);
        s.ms = sw.ms();
        s.cpu_ms = float(thread_cpu_ms() - cpu0);
    });
}

bool DetectorSet::finish(std::vector<Hypothesis> &out, StageTimes &times) {
    if (!has_started_) throw std::logic_error("DetectorSet::finish: no detection was started");
    times.add("detect_wait", worker_->wait());
    has_started_ = false;
    for (const auto &[name, ms] : started_.times.items) times.add("bg_" + name, ms);
    times.add("bg_detect", started_.ms);
    times.add("bg_detect_cpu", started_.cpu_ms);
    last = started_.found;
    last_frame = started_.frame;
    out.insert(out.end(), last.begin(), last.end());
    return started_.ran;
}

void DetectorSet::settle() {
    if (worker_) worker_->wait();
}

void DetectorSet::reset() {
    settle();
    has_started_ = false;
    started_ = Started{};
    for (auto &d : parts) d->reset();
}

} // namespace hw
