// Bounding-box placement on shelves (first fit, decreasing height): boxes
// come tallest first; each goes to the first shelf (row) with room left and
// at least its height, else opens a shelf below the last. Boxes on a shelf
// are the padding apart, shelves are the padding apart. Where charts come in
// many slightly different sizes (signal-scaled Lightmap Pack faces) rows of
// near-equal boxes waste less than the skyline's staircases.
#pragma once

#include <vector>

namespace lmrefine::pack {

class Shelves {
public:
    Shelves(double width, double height, double padding);

    // The position (left, top) of a w x h box, marked taken; false if it fits nowhere.
    bool place(double w, double h, double& x, double& y);

private:
    struct Shelf {
        double top, height, used;  // `used`: the next box's left
    };
    double width_, height_, padding_;
    std::vector<Shelf> shelves_;
};

}  // namespace lmrefine::pack
