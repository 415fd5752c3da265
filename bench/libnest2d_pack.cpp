// libnest2d (Debian libnest2d-dev) packing charts' outlines, for
// compare_libnest2d.py only: the measurement lmrefine's packer was compared
// with (docs/packer.md). Not part of lmrefine.
//
// stdin:  resolution padding rotations iterations
//         chart_count, then per chart: n x0 y0 ... x(n-1) y(n-1)
//         (its outline in texels at scale 1, y up, counter-clockwise)
// stdout: scale seconds, then per chart: rotation tx ty (texels at that
//         scale; a point p goes to R(rotation) p + t)
// The largest global scale at which every outline lands in one bin, by
// bisection on the scale as lmrefine's packer searches it.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <vector>

#include <libnest2d/libnest2d.hpp>

namespace {

constexpr double kUnit = 1000.0;  // clipper's integer coordinates per texel

struct Outline {
    std::vector<double> xy;
};

bool nest_at(const std::vector<Outline>& charts, double scale, int resolution, double padding, bool rotations,
             std::vector<libnest2d::Item>& items) {
    using namespace libnest2d;
    items.clear();
    for (const Outline& chart : charts) {
        PathImpl path;
        const size_t n = chart.xy.size() / 2;
        // libnest2d wants clockwise outer contours (y up), closed.
        for (size_t k = n; k-- > 0;) {
            path.emplace_back(ClipperLib::cInt(std::llround(chart.xy[2 * k] * scale * kUnit)),
                              ClipperLib::cInt(std::llround(chart.xy[2 * k + 1] * scale * kUnit)));
        }
        path.push_back(path.front());
        items.emplace_back(path);
    }
    NestConfig<NfpPlacer, FirstFitSelection> config;
    config.placer_config.rotations = rotations ? std::vector<Radians>{0.0, Pi / 2.0} : std::vector<Radians>{0.0};
    // Default alignment (the pile centred in the bin): DONT_ALIGN with a
    // BOTTOM_LEFT start put every item in a bin of its own here.
    const Box bin(Point(0, 0), Point(ClipperLib::cInt(resolution * kUnit), ClipperLib::cInt(resolution * kUnit)));
    const size_t bins = nest(items, bin, Coord(std::llround(padding * kUnit)), config);
    if (bins != 1) return false;
    for (const auto& item : items) {
        if (item.binId() != 0) return false;
    }
    return true;
}

}  // namespace

int main() {
    int resolution = 0, rotations = 1, iterations = 8;
    double padding = 0;
    size_t count = 0;
    std::cin >> resolution >> padding >> rotations >> iterations >> count;
    std::vector<Outline> charts(count);
    double area = 0;
    for (Outline& chart : charts) {
        size_t n = 0;
        std::cin >> n;
        chart.xy.resize(2 * n);
        for (double& v : chart.xy) std::cin >> v;
        for (size_t k = 0; k < n; ++k) {
            const size_t j = (k + 1) % n;
            area += 0.5 * (chart.xy[2 * k] * chart.xy[2 * j + 1] - chart.xy[2 * j] * chart.xy[2 * k + 1]);
        }
    }
    const auto start = std::chrono::steady_clock::now();
    double low = 0, high = std::sqrt(double(resolution) * resolution / std::abs(area));
    std::vector<libnest2d::Item> items, best;
    for (int i = 0; i < iterations; ++i) {
        const double middle = low == 0 ? 0.7 * high : 0.5 * (low + high);
        if (nest_at(charts, middle, resolution, padding, rotations != 0, items)) {
            low = middle;
            best = items;
        } else {
            high = middle;
        }
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("%.9g %.6f\n", low, seconds);
    for (const auto& item : best) {
        std::printf("%.12g %.12g %.12g\n", double(item.rotation()), double(libnest2d::getX(item.translation())) / kUnit,
                    double(libnest2d::getY(item.translation())) / kUnit);
    }
    return 0;
}
