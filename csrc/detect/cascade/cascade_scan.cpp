#include "detect/cascade/cascade_scan.hpp"
#include "base/stopwatch.hpp"
#include "base/worker_pool.hpp"
#include "detect/cascade/haar_cascade.hpp"
#include "detect/vehicle_verifier.hpp"

#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hw {

namespace {

// A model file that does not load is reported under the key that names it, in one line: OpenCV's own
// exceptions carry a source file and line and a newline.
template <class Load> auto load_keyed(const std::string &key, const std::string &path, Load &&load) {
    try {
        return load();
    } catch (const cv::Exception &e) {
        throw std::invalid_argument(key + ": '" + path + "' cannot be read as its model (" + e.err + ")");
    }
}

// The suppression: indices of the boxes kept, most confident first (ties in index order), each box dropped that
// overlaps a kept more confident one at IoU >= nms_iou (two groups on one vehicle). (cues/verify.hpp's
// strongest_apart drops only above its threshold.)
std::vector<size_t> kept_apart(const std::vector<float> &confidence, const std::vector<cv::Rect2f> &boxes,
                               double nms_iou) {
    std::vector<size_t> order(confidence.size()), kept;
    for (size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return confidence[a] > confidence[b]; });
    for (const size_t k : order) {
        bool dup = false;
        for (size_t i = 0; i < kept.size() && !dup; ++i) dup = box_iou(boxes[kept[i]], boxes[k]) >= nms_iou;
        if (!dup) kept.push_back(k);
    }
    return kept;
}

// The second looks at the boxes the first look believes (p >= min_p), by look_again(which), which lowers p[k] and
// moves boxes[k] of each k in `which`. With nms_iou < 1 (the suppression that follows) a believed box that overlaps
// (nms_iou) one already judged twice and still more confident than this box's first look would be dropped by the
// suppression whatever its second look says, as long as that one is kept: it is left unjudged. The believed boxes
// are judged again in rounds, most confident first, a box overlapping one judged in the same round waiting for the
// next (most rounds: one box a vehicle); then a box left unjudged that the suppression as it stands would keep (its
// cover was itself suppressed) is judged after all, until none is. With nms_iou >= 1 every believed box is judged.
template <class Look>
void judge_again(std::vector<float> &p, const std::vector<cv::Rect2f> &boxes, double min_p, double nms_iou,
                 Look &&look_again) {
    std::vector<size_t> believed;
    for (size_t k = 0; k < p.size(); ++k)
        if (p[k] >= min_p) believed.push_back(k);
    std::stable_sort(believed.begin(), believed.end(), [&](size_t a, size_t b) { return p[a] > p[b]; });
    const bool lazy = nms_iou < 1.0;
    std::vector<char> twice(p.size(), 0), left(p.size(), 0), skipped(p.size(), 0);
    for (const size_t k : believed) left[k] = 1;
    for (;;) {
        for (;;) {
            std::vector<size_t> which;
            for (const size_t k : believed) {
                if (!left[k]) continue;
                bool covered = false, wait = false;
                for (size_t j = 0; lazy && !skipped[k] && j < p.size() && !covered; ++j)
                    covered = twice[j] && p[j] > p[k] && box_iou(boxes[j], boxes[k]) >= nms_iou;
                for (size_t i = 0; lazy && !covered && i < which.size() && !wait; ++i)
                    wait = box_iou(boxes[which[i]], boxes[k]) >= nms_iou;
                if (covered) {
                    left[k] = 0;
                    skipped[k] = 1;
                } else if (!wait) {
                    which.push_back(k);
                }
            }
            if (which.empty()) break;
            look_again(which);
            for (const size_t k : which) {
                twice[k] = 1;
                left[k] = 0;
            }
        }
        if (!lazy) return;
        // the suppression, on the boxes as they stand: a skipped box it keeps is judged after all
        bool again = false;
        for (const size_t k : kept_apart(p, boxes, nms_iou))
            if (skipped[k] && !twice[k]) {
                left[k] = 1;  // skipped stays set: no cover is looked for again
                again = true;
            }
        if (!again) return;
    }
}

} // namespace

CascadeDetector::CascadeDetector(const CascadeParams &p) : p_(p) {
    if (p_.model.empty())
        throw std::invalid_argument("cascade.model: no cascade XML given (Headway's Python side fills in the shipped one)");
    if (p_.opencv_scan) {  // OpenCV's scan: also runs what HaarCascade does not read (tilted features)
        cc_ = std::make_unique<cv::CascadeClassifier>();
        if (!cc_->load(p_.model))
            throw std::invalid_argument("cascade.model: OpenCV cannot load '" + p_.model +
                                        "' as a cascade XML; train one with `headway train cascade` or leave the key empty");
        if (p_.step_px != 2)
            throw std::invalid_argument("cascade.opencv_scan: OpenCV's scan steps 2 px; set cascade.step_px to 2 with it");
        win_ = cc_->getOriginalWindowSize();
    } else {
        haar_ = load_keyed("cascade.model", p_.model, [&] { return std::make_unique<HaarCascade>(p_.model, p_.scan_lanes); });
        win_ = haar_->window();
        for (int k = 1; k < p_.threads; ++k) helpers_.push_back(std::make_unique<HaarCascade>(*haar_));
    }
    pool_ = std::make_unique<WorkerPool>(p_.threads);
    if (!p_.verifier.empty() && p_.verifier != "off")
        verifier_ = load_keyed("cascade.verifier", p_.verifier, [&] {
            return make_vehicle_verifier(p_.verifier, p_.verify_mirrored, p_.mirror_min_p, p_.verifier_dnn);
        });
    if (verifier_) verifier_->set_pool(pool_.get());
    if (p_.road.shape.max_height_m <= p_.min_vehicle_height_m)
        throw std::invalid_argument("vehicle_shape.max_height_m (" + cv::format("%g", p_.road.shape.max_height_m) +
                                    " m) must exceed cascade.min_vehicle_height_m (" +
                                    cv::format("%g", p_.min_vehicle_height_m) +
                                    " m): no window size has rows to scan; raise the first or lower the second");
}

CascadeDetector::~CascadeDetector() = default;

namespace {

const double kCarHeightM = 1.5;  // m; the vehicle whose range tracked_far_m states (a car)

struct Raw {
    cv::Rect2f box;
    float weight;
    int scale;  // index of the window size
};

} // namespace

std::vector<CascadeDetection> CascadeDetector::detect(const cv::Mat &gray, const LaneModel &lanes,
                                                      const CameraParams &cam, int slice,
                                                      int slices, StageTimes *times) const {
    return judge(gray, cam, groups(gray, lanes, cam, slice, slices, times), times);
}

std::vector<CascadeDetection> CascadeDetector::groups(const cv::Mat &gray, const LaneModel &lanes,
                                                      const CameraParams &cam, int slice, int slices,
                                                      StageTimes *times) const {
    CV_Assert(slices >= 1 && slice >= 0 && slice < slices);
    Stopwatch whole;
    struct Report {  // on every way out: the call's time
        StageTimes *times;
        const Stopwatch &whole;
        ~Report() {
            if (times) times->add("cascade", float(whole.ms()));
        }
    } report{times, whole};
    CV_Assert(gray.type() == CV_8UC1);
    const RoadPrior prior = make_road_prior(gray.size(), lanes, cam, p_.road);
    std::vector<Raw> raw;
    if (prior.empty()) return {};
    const double yh = prior.horizon_row, hc = cam.height_m;
    const double max_h = p_.max_window_frac * gray.rows;
    std::vector<cv::Rect> rects;
    std::vector<int> levels;
    std::vector<double> weights;
    // Plan every window size's band first (rows where its bottom may lie, columns of the road area), then scan
    // the sizes of this call's slice: all of them, or one block of `slices` (tracked_slices).
    struct Band {
        double f, ws, hs;
        int x0, y0, x1, y1, in0, in1;
        double windows;  // windows the band holds at step_px: what its scan costs
    };
    std::vector<Band> bands;
    for (double f = 1.0; win_.height * f <= max_h; f *= p_.scale_factor) {
        const double hs = win_.height * f, ws = win_.width * f;
        if (hs < p_.min_window_px) continue;
        // rows where the window's bottom may lie (flat road, vehicle heights H_min..H_max)
        const double yb0 = std::max<double>(prior.y_top, yh + hs * hc / p_.road.shape.max_height_m);
        const double yb1 = std::min<double>(gray.rows, yh + hs * hc / p_.min_vehicle_height_m);
        if (yb1 <= yb0) continue;
        // columns: the road area at those rows, half a window wider each side
        int xl = gray.cols, xr = -1;
        for (int y = int(yb0); y < std::min<int>(int(std::ceil(yb1)), prior.y_bottom); ++y) {
            if (!prior.contains_row(y) || prior.left(y) > prior.right(y)) continue;
            xl = std::min(xl, prior.left(y));
            xr = std::max(xr, prior.right(y));
        }
        if (xr < xl) {  // bottom rows below the scanned road (near vehicles): the last road row's span
            const int y = prior.y_bottom - 1;
            if (yb1 < prior.y_bottom || prior.left(y) > prior.right(y)) continue;
            xl = prior.left(y); xr = prior.right(y);
        }
        const int beyond = int(p_.border_frac * ws);  // px a window may reach past the left or right border
        const int x0 = std::max(-beyond, int(xl - ws / 2)), x1 = std::min(gray.cols + beyond, int(xr + ws / 2) + 1);
        const int y0 = std::max(0, int(yb0 - hs)), y1 = std::min(gray.rows, int(std::ceil(yb1)) + 1);
        if (x1 - x0 < ws + 1 || y1 - y0 < hs + 1) continue;
        const int in0 = std::max(x0, 0), in1 = std::min(x1, gray.cols);
        if (in1 - in0 < 2) continue;
        const double step = p_.step_px * f;
        bands.push_back({f, ws, hs, x0, y0, x1, y1, in0, in1,
                         std::max(0.0, (x1 - x0 - ws) / step + 1) * std::max(0.0, (y1 - y0 - hs) / step + 1)});
    }
    // The far sizes (tracked_far_m: window heights of a car beyond that range) are scanned every time; the
    // rest, all sizes without it, are cut into `slices` blocks.
    size_t far = 0;
    if (slices > 1 && p_.tracked_far_m > 0.0)
        while (far < bands.size() && bands[far].hs <= cam.fy * kCarHeightM / p_.tracked_far_m) ++far;
    size_t first = far, last = bands.size();
    if (slices > 1) {
        // Contiguous blocks of sizes (a vehicle's sizes stay together: it is grouped and verified once) of about
        // equal cost: a block closes where taking the next size would pass the remaining windows' fair share by
        // more than stopping leaves it short; every block gets a size while there are sizes enough.
        double left = 0.0;
        for (size_t j = far; j < bands.size(); ++j) left += bands[j].windows;
        size_t i = far;
        for (int k = 0; k < slices; ++k) {
            const size_t begin = i;
            const double share = left / double(slices - k);
            const bool last_block = k == slices - 1;  // takes the rest
            double acc = 0.0;
            while (i < bands.size()) {
                if (!last_block && i > begin &&
                    (acc + bands[i].windows - share > share - acc || bands.size() - i <= size_t(slices - 1 - k)))
                    break;
                acc += bands[i].windows;
                ++i;
            }
            left -= acc;
            if (k == slice) { first = begin; last = i; break; }
        }
    }
    // Each size's windows, scanned on up to `threads` threads, a size at a time (base/worker_pool.hpp), each thread
    // with its own HaarCascade (scratch buffers); gathered in size order: the windows of one thread.
    std::vector<size_t> scanned;  // the bands of this call, smallest size first: the far ones, then the slice
    for (size_t j = 0; j < far; ++j) scanned.push_back(j);
    for (size_t j = first; j < last; ++j) scanned.push_back(j);
    const size_t nb = scanned.size();
    std::vector<std::vector<HaarWindow>> found(nb);
    auto scan_band = [&](size_t k, const HaarCascade *haar) {
        const Band &bd = bands[scanned[k]];
        const double f = bd.f;
        cv::Mat roi = gray(cv::Rect(bd.in0, bd.y0, bd.in1 - bd.in0, bd.y1 - bd.y0)), padded, band;
        if (bd.in0 > bd.x0 || bd.in1 < bd.x1)  // the band reaches past a border: black there
            cv::copyMakeBorder(roi, padded, 0, 0, bd.in0 - bd.x0, bd.x1 - bd.in1, cv::BORDER_CONSTANT, cv::Scalar(0)),
                roi = padded;
        const cv::Size sz(int(std::lround(roi.cols / f)), int(std::lround(roi.rows / f)));
        if (sz.width <= win_.width || sz.height <= win_.height) return;
        if (f > 1.0) cv::resize(roi, band, sz, 0, 0, cv::INTER_LINEAR);
        else band = roi;
        if (cc_) {  // the reference: OpenCV's own scan at scale 1 (step 2)
            rects.clear(); levels.clear(); weights.clear();
            cc_->detectMultiScale(band, rects, levels, weights, 1.5, 0, 0, win_, win_, true);
            for (size_t i = 0; i < rects.size(); ++i) found[k].push_back({rects[i].x, rects[i].y, weights[i]});
        } else {
            haar->scan(band, p_.step_px, found[k]);  // the same windows, faster (haar_cascade.hpp)
        }
    };
    if (cc_) {  // OpenCV's scan keeps its own threads
        for (size_t k = 0; k < nb; ++k) scan_band(k, nullptr);
    } else {
        pool_->run(int(nb), [&](int k, int slot) {  // slot 0: haar_, slot k: helpers_[k - 1]
            scan_band(size_t(k), slot == 0 ? haar_.get() : helpers_[size_t(slot - 1)].get());
        });
    }
    for (size_t k = 0; k < nb; ++k) {  // the window size's index in this call: one bucket of by_x below
        const Band &bd = bands[scanned[k]];
        for (const HaarWindow &w : found[k])
            raw.push_back({cv::Rect2f(float(bd.x0 + w.x * bd.f), float(bd.y0 + w.y * bd.f), float(bd.ws), float(bd.hs)),
                           float(w.stage_sum), int(k)});
    }
    // group: strongest first, every window overlapping a group's seed joins it. OpenCV's detectMultiScale scans in
    // parallel and returns the windows in a thread-dependent order, and stage sums tie (they are sums of a few
    // stump values): a total order (sum, then position) makes the groups, hence the tracks, the same on every run.
    std::sort(raw.begin(), raw.end(), [](const Raw &a, const Raw &b) {
        if (a.weight != b.weight) return a.weight > b.weight;
        if (a.box.y != b.box.y) return a.box.y < b.box.y;
        if (a.box.x != b.box.x) return a.box.x < b.box.x;
        return a.box.width < b.box.width;
    });
    // The windows of each scale sorted by x: a window can reach IoU >= group_iou > 0 with the seed only if it
    // overlaps it, x in (x_seed - w, x_seed + w_seed), and its area is within a factor group_iou of the seed's;
    // only those are tested (the same windows the test of every pair finds, summed in the same order).
    std::vector<std::vector<std::pair<float, int>>> by_x(nb);
    for (size_t i = 0; i < raw.size(); ++i) by_x[size_t(raw[i].scale)].push_back({raw[i].box.x, int(i)});
    for (auto &v : by_x) std::sort(v.begin(), v.end());
    std::vector<char> used(raw.size(), 0);
    std::vector<int> members;
    std::vector<CascadeDetection> out;
    const cv::Rect2f image(0.f, 0.f, float(gray.cols), float(gray.rows));
    for (size_t i = 0; i < raw.size(); ++i) {
        if (used[i]) continue;
        const cv::Rect2f &seed = raw[i].box;
        members.clear();
        for (const auto &v : by_x) {
            if (v.empty()) continue;
            const cv::Rect2f &other = raw[size_t(v.front().second)].box;  // every window of a scale has one size
            const float ratio = other.area() / seed.area();
            if (ratio < p_.group_iou || ratio * p_.group_iou > 1.f) continue;
            auto it = std::lower_bound(v.begin(), v.end(), std::make_pair(seed.x - other.width - 1.f, -1));
            for (; it != v.end() && it->first <= seed.x + seed.width + 1.f; ++it)
                if (!used[size_t(it->second)] && box_iou(seed, raw[size_t(it->second)].box) >= p_.group_iou)
                    members.push_back(it->second);
        }
        std::sort(members.begin(), members.end());
        double l = 0, t = 0, r = 0, b = 0;
        const int n = int(members.size());
        for (const int j : members) {
            used[size_t(j)] = 1;
            l += raw[size_t(j)].box.x; t += raw[size_t(j)].box.y; r += raw[size_t(j)].box.br().x; b += raw[size_t(j)].box.br().y;
        }
        if (n < p_.min_neighbors) continue;
        CascadeDetection d;
        // a group reaching past a border (border_frac) is the vehicle's part in the image, as annotations box it
        d.box = cv::Rect2f(float(l / n), float(t / n), float((r - l) / n), float((b - t) / n)) & image;
        d.neighbors = n;
        d.stage_sum = raw[i].weight;
        d.confidence = float(n / (n + p_.neighbors_half));
        d.placed = d.box;
        out.push_back(d);
        if (p_.max_groups > 0 && int(out.size()) >= p_.max_groups) break;  // the seeds come strongest first
    }
    return out;
}

std::vector<CascadeDetection> CascadeDetector::judge(const cv::Mat &gray, const CameraParams &cam,
                                                     std::vector<CascadeDetection> out, StageTimes *times) const {
    Stopwatch whole;
    double verifier_ms = 0.0;
    struct Report {  // on every way out: the call's time, split into the verifier's and the rest
        StageTimes *times;
        const Stopwatch &whole;
        const double &verifier_ms;
        ~Report() {
            if (!times) return;
            times->add("cascade", float(whole.ms() - verifier_ms));
            times->add("verifier", float(verifier_ms));
        }
    } report{times, whole, verifier_ms};
    const double hc = cam.height_m;
    const cv::Rect2f image(0.f, 0.f, float(gray.cols), float(gray.rows));
    const VehicleVerifier *verifier = verifier_.get();
    if (verifier) {  // every group of the frame at once (the CNN verifier runs them as one batch)
        Stopwatch sv;
        std::vector<cv::Rect2f> boxes;
        std::vector<int> ns;
        std::vector<size_t> judged;  // groups of fewer than verify_min_neighbors windows keep n / (n + half)
        for (size_t i = 0; i < out.size(); ++i) {
            if (out[i].neighbors < p_.verify_min_neighbors) continue;
            judged.push_back(i);
            boxes.push_back(out[i].box);
            ns.push_back(out[i].neighbors);
        }
        // The box output places every box: its probability, the suppression and the box reported go by where it
        // is placed.
        const bool refine = p_.refine_boxes && verifier->has_box_output();
        // the image's integral once for every look (a CNN verifier's crops are averaged from it)
        const cv::Mat ii = verifier->integral_of(gray);
        const cv::Mat *integral = ii.empty() ? nullptr : &ii;
        std::vector<float> p = refine ? verifier->judge(gray, boxes, ns, cam.horizon_row(), hc, integral)
                                      : verifier->probabilities(gray, boxes, ns, cam.horizon_row(), hc, integral);
        for (auto &b : boxes) b &= image;  // moved past a border: the part in the image (judged, if again, there)
        if (refine && p_.rejudge_refined) {
            // only what the first look believes: the second can only lower a probability (min of the two)
            const auto look_again = [&](const std::vector<size_t> &which) {
                std::vector<cv::Rect2f> second;
                std::vector<int> second_n;
                for (const size_t k : which) {
                    second.push_back(boxes[k]);
                    second_n.push_back(ns[k]);
                }
                // the second look's box output, where rejudge_move asks for it: a second, damped step (the output
                // learned one step from a group's box; on a moved box its offsets are a second estimate of what
                // is left)
                std::vector<cv::Rect2f> moved = second;
                const std::vector<float> again =
                    p_.rejudge_move > 0.0
                        ? verifier->judge(gray, moved, second_n, cam.horizon_row(), hc, integral)
                        : verifier->probabilities(gray, second, second_n, cam.horizon_row(), hc, integral);
                const float s = float(p_.rejudge_move);
                for (size_t j = 0; j < which.size(); ++j) {
                    p[which[j]] = std::min(p[which[j]], again[j]);
                    const cv::Rect2f &a = second[j], &b = moved[j];
                    boxes[which[j]] = cv::Rect2f(a.x + s * (b.x - a.x), a.y + s * (b.y - a.y),
                                                 a.width + s * (b.width - a.width), a.height + s * (b.height - a.height)) &
                                      image;
                }
            };
            judge_again(p, boxes, p_.rejudge_min_p, p_.lazy_rejudge ? p_.nms_iou : 1.0, look_again);
        }
        for (size_t k = 0; k < judged.size(); ++k) {
            out[judged[k]].confidence = p[k];
            out[judged[k]].placed = boxes[k];  // moved by the box output when the verifier has one and `refine`
            out[judged[k]].box = boxes[k];
        }
        verifier_ms = sv.ms();
    }
    if (p_.nms_iou >= 1.0) return out;
    std::vector<float> confidence;
    std::vector<cv::Rect2f> placed;
    for (const auto &d : out) {
        confidence.push_back(d.confidence);
        placed.push_back(d.placed);
    }
    std::vector<CascadeDetection> kept;
    for (const size_t k : kept_apart(confidence, placed, p_.nms_iou)) kept.push_back(out[k]);
    return kept;
}

} // namespace hw
