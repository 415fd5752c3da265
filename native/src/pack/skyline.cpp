#include "skyline.h"

#include <algorithm>
#include <cmath>

namespace lmrefine::pack {

Skyline::Skyline(double width, double height, double padding)
    : width_(width), height_(height), padding_(padding), segments_{{0.0, 0.0}} {}

double Skyline::top_over(size_t k, double x, double w) const {
    double top = 0.0;
    const double end = x + w;
    for (; k < segments_.size() && segments_[k].x < end; ++k) top = std::max(top, segments_[k].top);
    return top;
}

bool Skyline::find(double w, double h, double& x, double& y) const {
    bool found = false;
    double best_bottom = INFINITY;
    for (size_t k = 0; k < segments_.size(); ++k) {
        const double left = segments_[k].x;
        if (left + w > width_) break;
        // The box owns its padding to the right (up to the atlas's edge).
        const double top = top_over(k, left, std::min(w + padding_, width_ - left));
        if (top + h > height_ || top + h >= best_bottom) continue;
        best_bottom = top + h;
        x = left;
        y = top;
        found = true;
    }
    return found;
}

void Skyline::place(double x, double y, double w, double h) {
    const double end = std::min(x + w + padding_, width_);
    const double top = y + h + padding_;
    std::vector<Segment> next;
    next.reserve(segments_.size() + 2);
    for (size_t k = 0; k < segments_.size(); ++k) {
        const double a = segments_[k].x, b = k + 1 < segments_.size() ? segments_[k + 1].x : width_;
        if (b <= x || a >= end) {
            if (a >= end && (next.empty() || next.back().x < x)) next.push_back({x, top});
            next.push_back(segments_[k]);
            continue;
        }
        if (a < x) next.push_back(segments_[k]);  // its part left of the box
        if (next.empty() || next.back().x < x) next.push_back({x, top});
        if (b > end) next.push_back({end, segments_[k].top});  // its part right of the owned columns
    }
    if (next.empty() || next.back().x < x) next.push_back({x, top});
    // Neighbours at the same top are one segment.
    segments_.clear();
    for (const Segment& s : next) {
        if (!segments_.empty() && segments_.back().top == s.top) continue;
        segments_.push_back(s);
    }
}

}  // namespace lmrefine::pack
