#include "shelves.h"

namespace lmrefine::pack {

Shelves::Shelves(double width, double height, double padding) : width_(width), height_(height), padding_(padding) {}

bool Shelves::place(double w, double h, double& x, double& y) {
    for (Shelf& shelf : shelves_) {
        if (h <= shelf.height && shelf.used + w <= width_) {
            x = shelf.used;
            y = shelf.top;
            shelf.used += w + padding_;
            return true;
        }
    }
    const double top = shelves_.empty() ? 0.0 : shelves_.back().top + shelves_.back().height + padding_;
    if (top + h > height_ || w > width_) return false;
    shelves_.push_back({top, h, w + padding_});
    x = 0.0;
    y = top;
    return true;
}

}  // namespace lmrefine::pack
