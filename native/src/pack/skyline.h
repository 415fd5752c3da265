// Bounding-box placement at continuous positions: a skyline packer. Each
// chart is its bounding box (the chart kInset inside it); a box owns itself
// grown by the padding to the right and below, and owned regions do not
// overlap, so any two charts are at least the padding apart along one axis.
// Exact for rectangular charts (Lightmap Pack makes one per face), where
// the footprint grid loses up to a grid cell per chart and per gutter.
#pragma once

#include <cstddef>
#include <vector>

namespace lmrefine::pack {

class Skyline {
public:
    Skyline(double width, double height, double padding);

    // The position (left, top) of a w x h box with the lowest bottom, then
    // the leftmost; false if it fits nowhere.
    bool find(double w, double h, double& x, double& y) const;
    // Marks the box at (x, y) (as find returned it) and its padding taken.
    void place(double x, double y, double w, double h);

private:
    // Segment k covers columns [x, next segment's x) (the last: to the
    // width) and is free from row `top` down.
    struct Segment {
        double x, top;
    };
    // The lowest top at which [x, x + w) is free, scanning from segment k.
    double top_over(std::size_t k, double x, double w) const;

    double width_, height_, padding_;
    std::vector<Segment> segments_;
};

}  // namespace lmrefine::pack
