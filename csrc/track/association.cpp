#include "track/association.hpp"

#include <algorithm>
#include <limits>

namespace hw {

std::vector<int> hungarian(const cv::Mat_<double> &cost, double forbidden) {
    // Kuhn-Munkres with potentials (O(n^3)) on the matrix padded to a square with zeros: a row or column left
    // unpaired costs 0, a forbidden pair more than all allowed pairs together (so it is made only where nothing
    // else is left, and then reported as unpaired).
    const int rows = cost.rows, cols = cost.cols, n = std::max(rows, cols);
    std::vector<int> out(size_t(rows), -1);
    if (rows == 0 || cols == 0) return out;
    double big = 1.0;
    for (int i = 0; i < rows; ++i)
        for (int j = 0; j < cols; ++j)
            if (cost(i, j) < forbidden) big += std::abs(cost(i, j));
    auto c = [&](int i, int j) {  // 1-based, padded
        if (i > rows || j > cols) return 0.0;
        const double v = cost(i - 1, j - 1);
        return v >= forbidden ? big : v;
    };
    const double inf = std::numeric_limits<double>::infinity();
    std::vector<double> u(size_t(n) + 1, 0.0), v(size_t(n) + 1, 0.0);
    std::vector<int> match(size_t(n) + 1, 0), way(size_t(n) + 1, 0);  // match[j]: row of column j
    for (int i = 1; i <= n; ++i) {
        match[0] = i;
        int j0 = 0;
        std::vector<double> minv(size_t(n) + 1, inf);
        std::vector<char> used(size_t(n) + 1, 0);
        do {
            used[size_t(j0)] = 1;
            const int i0 = match[size_t(j0)];
            double delta = inf;
            int j1 = 0;
            for (int j = 1; j <= n; ++j) {
                if (used[size_t(j)]) continue;
                const double cur = c(i0, j) - u[size_t(i0)] - v[size_t(j)];
                if (cur < minv[size_t(j)]) { minv[size_t(j)] = cur; way[size_t(j)] = j0; }
                if (minv[size_t(j)] < delta) { delta = minv[size_t(j)]; j1 = j; }
            }
            for (int j = 0; j <= n; ++j) {
                if (used[size_t(j)]) { u[size_t(match[size_t(j)])] += delta; v[size_t(j)] -= delta; }
                else minv[size_t(j)] -= delta;
            }
            j0 = j1;
        } while (match[size_t(j0)] != 0);
        do {
            const int j1 = way[size_t(j0)];
            match[size_t(j0)] = match[size_t(j1)];
            j0 = j1;
        } while (j0);
    }
    for (int j = 1; j <= cols; ++j) {
        const int i = match[size_t(j)];
        if (i >= 1 && i <= rows && cost(i - 1, j - 1) < forbidden) out[size_t(i - 1)] = j - 1;
    }
    return out;
}

namespace {

// Pairs tracks[] with dets[] (index lists) at IoU >= min_iou by the Hungarian method; writes into `out`.
void assign(const cv::Mat_<float> &iou, const std::vector<int> &tracks, const std::vector<int> &dets, float min_iou,
            std::vector<int> &out) {
    if (tracks.empty() || dets.empty()) return;
    // cost -IoU: the assignment of the largest total overlap; an allowed pair always beats leaving both unpaired
    const double forbidden = 1.0;
    cv::Mat_<double> cost(int(tracks.size()), int(dets.size()));
    for (size_t i = 0; i < tracks.size(); ++i)
        for (size_t j = 0; j < dets.size(); ++j) {
            const float o = iou(tracks[i], dets[j]);
            cost(int(i), int(j)) = o >= min_iou && o > 0.f ? -double(o) : forbidden;
        }
    const std::vector<int> a = hungarian(cost, forbidden);
    for (size_t i = 0; i < tracks.size(); ++i)
        if (a[i] >= 0) out[size_t(tracks[i])] = dets[size_t(a[i])];
}

} // namespace

std::vector<int> associate(const cv::Mat_<float> &iou, const std::vector<float> &scores, const AssociationParams &p) {
    CV_Assert(iou.cols == int(scores.size()));
    std::vector<int> out(size_t(iou.rows), -1);
    std::vector<int> all(size_t(iou.rows)), high, low;
    for (int i = 0; i < iou.rows; ++i) all[size_t(i)] = i;
    for (int j = 0; j < iou.cols; ++j)
        if (scores[size_t(j)] >= p.low_score) (scores[size_t(j)] >= p.high_score ? high : low).push_back(j);
    assign(iou, all, high, float(p.match_iou), out);
    std::vector<int> left;
    for (int i = 0; i < iou.rows; ++i)
        if (out[size_t(i)] < 0) left.push_back(i);
    assign(iou, left, low, float(p.low_match_iou), out);
    return out;
}

int take_best_unused(const std::vector<float> &iou, std::vector<bool> &used, float min_iou) {
    int best = -1;
    float best_iou = min_iou;
    for (size_t i = 0; i < iou.size(); ++i)
        if (!used[i] && iou[i] >= best_iou) { best_iou = iou[i]; best = int(i); }
    if (best >= 0) used[size_t(best)] = true;
    return best;
}

} // namespace hw
