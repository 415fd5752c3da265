// The scale search: the largest global scale at which a greedy placement
// places every chart, for two placements, keeping the larger scale: the
// first fit of texel footprints (occupancy.cpp; each trial rasterizes every
// chart at the trial's scale, footprint.cpp) and the skyline of bounding
// boxes at continuous positions (skyline.cpp). Charts go longest side first.
#include "lmrefine/pack/packer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <numeric>
#include <string>

#include <glm/common.hpp>

#include "footprint.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"
#include "lmrefine/layout/chart.h"
#include "occupancy.h"
#include "shelves.h"
#include "skyline.h"
#include "weld.h"

namespace lmrefine {
namespace {

using pack::ChartPiece;
using pack::Footprint;

struct Placement {
    double x = 0, y = 0;  // the footprint's (or box's) corner, grid units
    int turns = 0;
};

struct Trial {
    bool fits = false;
    std::vector<Placement> placements;  // per chart
    int64_t texels = 0;        // footprint cells placed
    int64_t total_texels = 0;  // footprint cells of every chart (upright)
    double bottom = 0;         // the lowest grid row the placed charts reach
};

// Footprint bitmaps reused by the trials and by later calls: a fresh bitmap
// per chart and trial cost more in page faults than its rasterization
// (glibc gives a freed block back to the system and the next one is
// faulted in anew), and so did a pool per call (docs/packer.md). Up to
// kKeptBytes stay allocated between calls. The lock is only tried: a
// thread that does not get it (or a child made by fork() while another
// thread held it) allocates or frees as if there were no pool.
class BitmapPool {
public:
    static constexpr size_t kKeptBytes = size_t(16) << 20;

    std::vector<uint8_t> take() {
        std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
        if (!lock.owns_lock() || free_.empty()) return {};
        std::vector<uint8_t> bits = std::move(free_.back());
        free_.pop_back();
        kept_ -= bits.capacity();
        return bits;
    }
    // Keeps `bits` for a later take() if the pool has room; else the caller frees it.
    void give(std::vector<uint8_t>& bits) {
        std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
        if (bits.capacity() == 0 || !lock.owns_lock() || kept_ + bits.capacity() > kKeptBytes) return;
        kept_ += bits.capacity();
        free_.push_back(std::move(bits));
    }

private:
    std::mutex mutex_;
    std::vector<std::vector<uint8_t>> free_;
    size_t kept_ = 0;  // capacity held in free_
};

BitmapPool& footprint_bitmaps() {
    static BitmapPool pool;
    return pool;
}

struct Problem {
    const UvLayout& layout;
    const std::vector<ChartPiece>& pieces;
    const std::vector<glm::dvec2>& uvs;  // snapped (weld.h), double
    const std::vector<double>& scales;
    const PackOptions& options;
    const std::vector<glm::dvec2>& extents;  // per chart, its bounding box in grid units at global scale 1
};

// Longest side first, then the larger `weight`, ties by chart id: long
// charts placed first leave rows that shorter ones fill (docs/packer.md
// has the orders measured).
template <class Size>
std::vector<int32_t> placement_order(size_t count, Size size_of) {
    std::vector<int32_t> order(count);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int32_t a, int32_t b) { return size_of(a) > size_of(b); });
    return order;
}

// Footprints of the same cells (charts of one shape at one scale: Lightmap
// Pack's faces often are) get one id, so a trial can remember where the last
// of them was placed: blocking only adds cells, so every corner the scan
// passed for it before is still ruled out for the next.
std::vector<int32_t> shape_ids(const std::vector<Footprint>& footprints) {
    const auto hash_of = [](const Footprint& f) {
        uint64_t h = 1469598103934665603ull;
        const auto mix = [&h](uint64_t v) { h = (h ^ v) * 1099511628211ull; };
        mix(uint64_t(uint32_t(f.covered.width)));
        mix(uint64_t(uint32_t(f.covered.height)));
        for (const int32_t o : f.covered.offsets) mix(uint64_t(uint32_t(o)));
        for (const pack::Span& span : f.covered.spans) mix(uint64_t(uint32_t(span.first)) << 32 | uint32_t(span.second));
        return h;
    };
    const auto same = [](const Footprint& a, const Footprint& b) {
        return a.covered.width == b.covered.width && a.covered.height == b.covered.height &&
               a.covered.offsets == b.covered.offsets && a.covered.spans == b.covered.spans;
    };
    std::vector<uint64_t> hashes(footprints.size());
    for (size_t i = 0; i < footprints.size(); ++i) hashes[i] = hash_of(footprints[i]);
    std::vector<int32_t> order(footprints.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
        return hashes[size_t(a)] != hashes[size_t(b)] ? hashes[size_t(a)] < hashes[size_t(b)] : a < b;
    });
    std::vector<int32_t> ids(footprints.size(), -1);
    int32_t next = 0;
    for (size_t begin = 0; begin < order.size();) {
        size_t end = begin;
        while (end < order.size() && hashes[size_t(order[end])] == hashes[size_t(order[begin])]) ++end;
        // Equal hashes: compare the cells (a collision gets ids of its own).
        for (size_t i = begin; i < end; ++i) {
            const int32_t a = order[i];
            if (ids[size_t(a)] >= 0) continue;
            ids[size_t(a)] = next;
            for (size_t j = i + 1; j < end; ++j) {
                const int32_t b = order[j];
                if (ids[size_t(b)] < 0 && same(footprints[size_t(a)], footprints[size_t(b)])) ids[size_t(b)] = next;
            }
            ++next;
        }
        begin = end;
    }
    return ids;
}

// Places every chart at one global scale, or stops at the first that does not fit.
Trial run_trial(const Problem& problem, double global_scale, Progress* progress) {
    const size_t count = problem.pieces.size();
    const int turn_options = problem.options.rotate ? 2 : 1;
    std::vector<Footprint> footprints(count * size_t(turn_options));
    parallel_for(int64_t(count), 16, [&](int64_t begin, int64_t end) {
        BitmapPool& pool = footprint_bitmaps();
        std::vector<uint8_t> bits = pool.take();
        pack::FootprintScratch scratch;
        for (int64_t c = begin; c < end; ++c) {
            const auto local = pack::local_pixels(problem.pieces[size_t(c)], problem.uvs, global_scale * problem.scales[size_t(c)],
                                                  problem.options.width, problem.options.height);
            Footprint& upright = footprints[size_t(c) * size_t(turn_options)];
            upright = pack::make_footprint(problem.pieces[size_t(c)], problem.layout, local, problem.options.padding, bits,
                                           scratch);
            if (turn_options > 1) {
                footprints[size_t(c) * 2 + 1] = pack::turned_footprint(upright, scratch);
            }
        }
        pool.give(bits);
    });
    const std::vector<int32_t> order = placement_order(count, [&](int32_t c) {
        const Footprint& f = footprints[size_t(c) * size_t(turn_options)];
        return std::make_pair(std::max(f.covered.width, f.covered.height), f.texels);
    });

    Trial trial;
    trial.placements.resize(count);
    for (size_t c = 0; c < count; ++c) trial.total_texels += footprints[c * size_t(turn_options)].texels;
    pack::Occupancy occupancy(problem.options.width, problem.options.height);
    // Per footprint shape, the first row where one of its shape may still fit.
    const std::vector<int32_t> shape = shape_ids(footprints);
    std::vector<int32_t> first_row(footprints.size(), 0);
    for (size_t n = 0; n < count; ++n) {
        if ((n & 63) == 0 && progress && progress->cancelled()) return trial;
        const int32_t c = order[n];
        bool found = false;
        Placement best;
        for (int turns = 0; turns < turn_options; ++turns) {
            int x, y;
            // The other turn only wins at an earlier row (or the same row, further left).
            const size_t index = size_t(c) * size_t(turn_options) + size_t(turns);
            const Footprint& f = footprints[index];
            const int last_row = found ? int(best.y) : INT32_MAX;
            int32_t& from = first_row[size_t(shape[index])];
            if (!occupancy.first_fit(f, x, y, last_row, from)) {
                // No corner of this shape fits in rows up to last_row now, nor will later.
                if (last_row != INT32_MAX) from = std::max(from, last_row + 1);
                continue;
            }
            from = y;  // corners before (x, y) were ruled out, and stay so
            if (!found || std::make_pair(double(y), double(x)) < std::make_pair(best.y, best.x)) best = {double(x), double(y), turns};
            found = true;
        }
        if (!found) return trial;
        const Footprint& f = footprints[size_t(c) * size_t(turn_options) + size_t(best.turns)];
        occupancy.place(f, int(best.x), int(best.y));
        trial.bottom = std::max(trial.bottom, best.y + f.covered.height);
        trial.texels += f.texels;
        trial.placements[size_t(c)] = best;
    }
    trial.fits = true;
    return trial;
}

// The box of chart c at a global scale: its bounding box and kInset on every side.
glm::dvec2 box_size(const Problem& problem, size_t c, double global_scale) {
    return problem.extents[c] * (global_scale * problem.scales[c]) + glm::dvec2(2.0 * pack::kInset);
}

// Places every chart's box, in `order`, at one global scale: place(box, p)
// fills the placement p (the box's corner, its turn) or returns false,
// and the trial stops at the first box that does not fit.
template <class Place>
Trial run_boxes(const Problem& problem, double global_scale, const std::vector<int32_t>& order, Progress* progress,
                Place place) {
    const size_t count = problem.pieces.size();
    Trial trial;
    trial.placements.resize(count);
    // Box areas stand in for footprint cells (the next guess after a failure).
    for (size_t c = 0; c < count; ++c) {
        const glm::dvec2 box = box_size(problem, c, global_scale);
        trial.total_texels += int64_t(std::ceil(box.x * box.y));
    }
    for (size_t n = 0; n < count; ++n) {
        if ((n & 63) == 0 && progress && progress->cancelled()) return trial;
        const int32_t c = order[n];
        if (problem.pieces[size_t(c)].corners.empty()) continue;
        const glm::dvec2 box = box_size(problem, size_t(c), global_scale);
        Placement& at = trial.placements[size_t(c)];
        if (!place(box, at)) return trial;
        trial.bottom = std::max(trial.bottom, at.y + (at.turns ? box.x : box.y));
        trial.texels += int64_t(std::ceil(box.x * box.y));
    }
    trial.fits = true;
    return trial;
}

// The skyline: longest side first; each box at the turn whose bottom is highest.
Trial run_skyline_trial(const Problem& problem, double global_scale, Progress* progress) {
    const std::vector<int32_t> order = placement_order(problem.pieces.size(), [&](int32_t c) {
        const glm::dvec2 box = box_size(problem, size_t(c), global_scale);
        return std::make_pair(std::max(box.x, box.y), box.x * box.y);
    });
    pack::Skyline skyline(problem.options.width, problem.options.height, problem.options.padding);
    return run_boxes(problem, global_scale, order, progress, [&](const glm::dvec2& box, Placement& best) {
        bool found = false;
        double best_bottom = INFINITY;
        for (int turns = 0; turns < (problem.options.rotate ? 2 : 1); ++turns) {
            const double w = turns ? box.y : box.x, h = turns ? box.x : box.y;
            double x, y;
            if (!skyline.find(w, h, x, y)) continue;
            // The turn whose box ends higher (then further left) wins.
            if (!found || std::make_pair(y + h, x) < std::make_pair(best_bottom, best.x)) {
                best = {x, y, turns};
                best_bottom = y + h;
            }
            found = true;
        }
        if (found) skyline.place(best.x, best.y, best.turns ? box.y : box.x, best.turns ? box.x : box.y);
        return found;
    });
}

// The shelves: boxes laid wide side down (when turns are allowed), tallest first.
Trial run_shelf_trial(const Problem& problem, double global_scale, Progress* progress) {
    const bool rotate = problem.options.rotate;
    auto turned = [&](const glm::dvec2& box) { return rotate && box.y > box.x; };
    const std::vector<int32_t> order = placement_order(problem.pieces.size(), [&](int32_t c) {
        const glm::dvec2 box = box_size(problem, size_t(c), global_scale);
        return turned(box) ? std::make_pair(box.x, box.y) : std::make_pair(box.y, box.x);
    });
    pack::Shelves shelves(problem.options.width, problem.options.height, problem.options.padding);
    return run_boxes(problem, global_scale, order, progress, [&](const glm::dvec2& box, Placement& at) {
        const int turns = int(turned(box));
        const glm::dvec2 laid = turns ? glm::dvec2(box.y, box.x) : box;
        at.turns = turns;
        return shelves.place(laid.x, laid.y, at.x, at.y);
    });
}

// The box placement is kept only when its scale beats the footprints' by this factor.
constexpr double kBoxMargin = 1.01;

struct Search {
    double scale = 0;  // the largest global scale that fitted
    Trial best;
    int trials = 0;
};

// The search ends when the largest scale that fits and the smallest that
// does not are this close.
constexpr double kCloseEnough = 1.004;
// The two scales tried around an estimate, this far apart (a hair closer
// than kCloseEnough; on the lattice below they may land up to 1e-4 farther
// apart, past it, and then one more round runs: keeping them within it
// measured no fewer trials, docs/packer.md), and how many rounds try them.
constexpr double kEstimateStep = 1.0039;
constexpr int kEstimateRounds = 6;

// Trial scales lie on a lattice, 1e-4 apart in log scale: layouts that
// differ by float rounding (a layout per corner and the same per loop) get
// the same bound to within the rounding, and would otherwise try scales that
// far apart, where an estimate aimed at the largest that fits can flip a
// trial.
double on_lattice(double scale) {
    constexpr double kStep = 1e-4;
    return std::exp(std::round(std::log(scale) / kStep) * kStep);
}

// The largest global scale in (0, bound] at which `run` places every chart
// in a grid `height` rows tall.
template <class Run>
Search search_scale(Run run, double bound, int height, const PackOptions& options, int32_t chart_count,
                    Progress* progress) {
    // Bracket [low, high): `low` fits, `high` does not (the bound never
    // fits better than exactly). Two trials per round (one per core); the
    // sequence of scales tried does not depend on the thread count, so
    // neither does the result.
    Search search;
    double low = 0.0, high = bound * 1.0000001;
    double guess = on_lattice(bound * 0.9);
    while (!search.best.fits) {
        Trial t = run(guess);
        ++search.trials;
        if (progress) {
            progress->check();
            progress->advance();
        }
        if (t.fits) {
            search.best = std::move(t);
            low = guess;
        } else {
            high = guess;
            // The next guess shrinks by the square root of the area that did
            // not fit (charts placed / all, in footprint cells), a little more.
            const double placed = t.total_texels > 0 ? double(t.texels) / double(t.total_texels) : 0.5;
            guess = on_lattice(guess * std::clamp(0.98 * std::sqrt(placed), 0.5, 0.97));
            if (guess < bound * 1e-9) {
                LMREFINE_THROW(InvalidArgument,
                               std::to_string(chart_count) + " charts do not fit a " + std::to_string(options.height) +
                                   " x " + std::to_string(options.width) + " atlas with padding " +
                                   std::to_string(options.padding) +
                                   " texels even at a tiny scale; use a higher resolution or a smaller padding");
            }
        }
    }
    // Charts go in rows from the top, so a trial that fits leaves the rows
    // below its lowest chart free, and the scale that would fill the atlas's
    // height is about low * sqrt(height / bottom) (on the bundled layouts
    // from half a percent above the largest that fits to three below,
    // docs/packer.md). A round tries a scale just below that estimate and
    // one just above (a fit and a failure that close end the search; both
    // fitting, the next estimate starts from the higher; both failing, the
    // next round tries just below the lower). Where these would leave the
    // bracket, and after kEstimateRounds rounds, a round cuts the bracket
    // in three.
    int estimated = 0;
    bool overshot = false;  // the last round's two scales both failed
    while (high / low > kCloseEnough) {
        const double ratio = high / low;
        double s1 = low * std::pow(ratio, 1.0 / 3.0), s2 = low * std::pow(ratio, 2.0 / 3.0);
        if (search.best.bottom > 0 && estimated < kEstimateRounds) {
            double e1, e2;
            if (overshot) {
                // Just below the failure (half a step: a fit there ends the search too).
                e2 = high / std::sqrt(kEstimateStep);
                e1 = e2 / kEstimateStep;
            } else {
                const double estimate = low * std::sqrt(double(height) / search.best.bottom);
                // At least half a step above `low`: a failure there ends the search too.
                e1 = std::max(estimate, low * kEstimateStep) / std::sqrt(kEstimateStep);
                e2 = e1 * kEstimateStep;
            }
            if (e1 > low && e2 < high) {
                s1 = e1, s2 = e2;
                ++estimated;
            }
        }
        Trial trials[2];
        const double tried[2] = {on_lattice(s1), on_lattice(s2)};
        parallel_for(2, 1, [&](int64_t begin, int64_t end) {
            for (int64_t k = begin; k < end; ++k) trials[k] = run(tried[k]);
        });
        search.trials += 2;
        if (progress) {
            progress->check();
            progress->advance(2);
        }
        if (trials[1].fits) {
            low = tried[1];
            search.best = std::move(trials[1]);
        } else if (trials[0].fits) {
            low = tried[0];
            high = tried[1];
            search.best = std::move(trials[0]);
        } else {
            high = tried[0];
        }
        overshot = !trials[0].fits;
    }
    search.scale = low;
    return search;
}

}  // namespace

PackResult pack_charts(const UvLayout& layout, const std::vector<int32_t>& triangle_chart, int32_t chart_count,
                       const std::vector<double>& scales, const PackOptions& options, Progress* progress) {
    if (options.width <= 0 || options.height <= 0) {
        LMREFINE_THROW(InvalidArgument, "resolution must be positive (got " + std::to_string(options.height) + " x " +
                                            std::to_string(options.width) + ")");
    }
    if (!(options.fixed_scale >= 0.0) || !std::isfinite(options.fixed_scale)) {
        LMREFINE_THROW(InvalidArgument, "fixed_scale must be finite and >= 0 (got " + std::to_string(options.fixed_scale) + ")");
    }
    if (!(options.padding >= 0.0) || options.padding > 1e4) {
        LMREFINE_THROW(InvalidArgument, "padding must be >= 0 texels and finite (got " + std::to_string(options.padding) + ")");
    }
    // Two charts that far apart cannot share the atlas (and each trial would dilate by it, slowly).
    if (options.padding > std::hypot(double(options.width), double(options.height))) {
        LMREFINE_THROW(InvalidArgument, "padding " + std::to_string(options.padding) +
                                            " texels is wider than the diagonal of the " +
                                            std::to_string(options.height) + " x " + std::to_string(options.width) +
                                            " atlas: give a padding of a few texels");
    }
    if (options.subdivision < 1 || options.subdivision > 8 ||
        int64_t(std::max(options.width, options.height)) * options.subdivision > (int64_t(1) << 15)) {
        LMREFINE_THROW(InvalidArgument, "subdivision must be in [1, 8] with resolution * subdivision <= 32768 (got " +
                                            std::to_string(options.subdivision) + " at " + std::to_string(options.height) +
                                            " x " + std::to_string(options.width) + "); use subdivision 1 for huge atlases");
    }
    if (int64_t(triangle_chart.size()) != layout.triangle_count) {
        LMREFINE_THROW(InvalidArgument, "charts must have one entry per triangle: got " + std::to_string(triangle_chart.size()) +
                                            " for " + std::to_string(layout.triangle_count) + " triangles");
    }
    if (int64_t(scales.size()) != chart_count) {
        LMREFINE_THROW(InvalidArgument, "scales must have one entry per chart: got " + std::to_string(scales.size()) +
                                            " for " + std::to_string(chart_count) + " charts");
    }
    for (int32_t c = 0; c < chart_count; ++c) {
        if (!(scales[size_t(c)] > 0.0) || !std::isfinite(scales[size_t(c)])) {
            LMREFINE_THROW(InvalidArgument, "scales must be finite and > 0: scales[" + std::to_string(c) + "] is " +
                                                std::to_string(scales[size_t(c)]));
        }
    }

    // Everything below works on the subdivided grid: "texels" are sub-texels.
    PackOptions grid = options;
    grid.width *= options.subdivision;
    grid.height *= options.subdivision;
    grid.padding *= options.subdivision;

    // Charts' triangles and UV indices; a UV index may belong to one chart only.
    std::vector<int32_t> chart_of_uv(size_t(layout.uv_count), -1);
    std::vector<ChartPiece> pieces(static_cast<size_t>(chart_count));
    for (int64_t t = 0; t < layout.triangle_count; ++t) {
        const int32_t c = triangle_chart[size_t(t)];
        if (c < 0 || c >= chart_count) {
            LMREFINE_THROW(InvalidArgument, "charts[" + std::to_string(t) + "] is " + std::to_string(c) +
                                                "; chart ids must be in [0, " + std::to_string(chart_count) + ")");
        }
        pieces[size_t(c)].triangles.push_back(t);
        for (int k = 0; k < 3; ++k) {
            const int32_t i = layout.triangles[3 * t + k];
            int32_t& owner = chart_of_uv[size_t(i)];
            if (owner >= 0 && owner != c) {
                LMREFINE_THROW(InvalidArgument, "charts: UV index " + std::to_string(i) + " is used by triangles of charts " +
                                                    std::to_string(owner) + " and " + std::to_string(c) +
                                                    "; a chart moves as a whole, so give every chart its own UV indices");
            }
            if (owner < 0) pieces[size_t(c)].corners.push_back(i);
            owner = c;
        }
    }
    for (auto& piece : pieces) std::sort(piece.corners.begin(), piece.corners.end());

    // Corners of one chart within the tolerance snap together (weld.h).
    const std::vector<glm::dvec2> uvs = pack::snapped_uvs(layout, chart_of_uv, options.weld_tolerance);

    // The area bound: the charts' total texel area at the global scale cannot
    // exceed the atlas; and the box bound: each chart's bounding box must fit
    // the atlas upright or turned (a needle of tiny area would otherwise ask
    // for footprints of billions of cells).
    double area = 0.0, box_area = 0.0, box_bound = INFINITY;
    std::vector<glm::dvec2> extents(size_t(chart_count), glm::dvec2(0.0));
    for (int32_t c = 0; c < chart_count; ++c) {
        const ChartPiece& piece = pieces[size_t(c)];
        double chart_area = 0.0;
        for (int64_t t : piece.triangles) {
            const int32_t* tri = layout.triangles + 3 * t;
            const glm::dvec2 a = uvs[size_t(tri[0])], b = uvs[size_t(tri[1])], d = uvs[size_t(tri[2])];
            chart_area += 0.5 * std::abs((b.x - a.x) * (d.y - a.y) - (b.y - a.y) * (d.x - a.x));
        }
        glm::dvec2 low(INFINITY), high(-INFINITY);
        for (int64_t i : piece.corners) {
            low = glm::min(low, uvs[size_t(i)]);
            high = glm::max(high, uvs[size_t(i)]);
        }
        const double s2 = scales[size_t(c)] * scales[size_t(c)] * grid.width * grid.height;
        area += chart_area * s2;
        if (piece.corners.empty()) continue;
        extents[size_t(c)] = (high - low) * glm::dvec2(grid.width, grid.height);
        box_area += (high.x - low.x) * (high.y - low.y) * s2;
        const double ex = (high.x - low.x) * scales[size_t(c)] * grid.width;   // cells at global scale 1
        const double ey = (high.y - low.y) * scales[size_t(c)] * grid.height;
        const double W = grid.width, H = grid.height;
        double fits = std::min(W / ex, H / ey);
        if (options.rotate) fits = std::max(fits, std::min(W / ey, H / ex));
        box_bound = std::min(box_bound, fits);
    }
    const double atlas = double(grid.width) * grid.height;
    double bound = area > 0 ? std::sqrt(atlas / area) : box_area > 0 ? std::sqrt(atlas / box_area) : 1.0;
    bound = std::min(bound, box_bound);
    if (!std::isfinite(bound) || bound > 1e12) bound = 1e12;

    Problem problem{layout, pieces, uvs, scales, grid, extents};
    PackResult result;
    result.scale_bound = bound;
    if (progress) progress->begin("pack", 60);
    const auto boxes_at = [&](double scale) {
        // Shelves first (rows of near-equal boxes), the skyline where they fail.
        Trial shelf = run_shelf_trial(problem, scale, progress);
        if (shelf.fits) return shelf;
        Trial sky = run_skyline_trial(problem, scale, progress);
        return sky.fits || sky.texels > shelf.texels ? sky : shelf;
    };
    Search search;
    bool boxes = false;
    if (options.fixed_scale > 0) {
        search.scale = options.fixed_scale;
        // Past the bound the charts cannot fit (and a chart's footprint may
        // not even fit in memory): no trial.
        const bool within_bound = search.scale <= bound * 1.0000001;
        if (within_bound) search.best = run_trial(problem, search.scale, progress);
        search.trials = 1;
        if (progress) progress->check();  // a cancelled trial stops early, and is no failure to fit
        if (!search.best.fits && options.boxes && within_bound) {
            search.best = boxes_at(search.scale);
            search.trials = 2;
            boxes = true;
            if (progress) progress->check();
        }
        if (!search.best.fits) {
            char scale[32];
            std::snprintf(scale, sizeof(scale), "%.6g", search.scale);
            LMREFINE_THROW(InvalidArgument, std::to_string(chart_count) + " charts do not fit a " +
                                                std::to_string(options.height) + " x " + std::to_string(options.width) +
                                                " atlas at global scale " + scale);
        }
    } else {
        search = search_scale([&](double scale) { return run_trial(problem, scale, progress); }, bound, grid.height,
                              options, chart_count, progress);
    }
    // Bounding boxes at continuous positions win where charts are
    // rectangles small against the grid (docs/packer.md).
    // Boxes cannot beat the footprints where the boxes' total area alone
    // would not fit at a larger scale (charts far from rectangles): skipped.
    const double box_scale_bound = box_area > 0 ? std::min(bound, std::sqrt(atlas / box_area)) : bound;
    if (options.fixed_scale <= 0 && options.boxes && box_scale_bound > kBoxMargin * search.scale) {
        try {
            Search box_search = search_scale(boxes_at, box_scale_bound, grid.height, options, chart_count, progress);
            search.trials += box_search.trials;
            // Each search ends within 0.4% of its largest scale: boxes must
            // beat the footprints by more than that (footprints are texel-exact).
            if (box_search.scale > kBoxMargin * search.scale) {
                box_search.trials = search.trials;
                search = std::move(box_search);
                boxes = true;
            }
        } catch (const InvalidArgument&) {  // no box placement at any scale: the footprints' stands
        }
    }
    const double low = search.scale;
    const Trial& best = search.best;
    result.trials = search.trials;
    result.boxes = boxes;
    result.global_scale = low;
    result.footprint_texels = double(best.texels) / (double(options.subdivision) * options.subdivision);

    // The output: each chart's local pixels at its placement, back to UV.
    result.uvs.assign(layout.uvs, layout.uvs + 2 * layout.uv_count);
    result.rotations.assign(size_t(chart_count), 0);
    result.transforms.assign(6 * size_t(chart_count), 0.0);
    const double w = grid.width, h = grid.height;
    for (int32_t c = 0; c < chart_count; ++c) {
        const ChartPiece& piece = pieces[size_t(c)];
        const Placement& at = best.placements[size_t(c)];
        const double scale = low * scales[size_t(c)];
        result.rotations[size_t(c)] = at.turns;
        std::vector<glm::dvec2> local = pack::local_pixels(piece, uvs, scale, grid.width, grid.height);
        // The width the turn is taken in: the footprint's, or the box's.
        const double turn_width = boxes ? box_size(problem, size_t(c), low).x : double(pack::footprint_size(local).x);
        for (auto& p : local) {
            if (at.turns) p = pack::turn_local(p, turn_width);
            p += glm::dvec2(at.x, at.y);
        }
        for (size_t k = 0; k < piece.corners.size(); ++k) {
            const size_t i = size_t(piece.corners[k]);
            result.uvs[2 * i] = float(std::clamp(local[k].x / w, 0.0, 1.0));
            result.uvs[2 * i + 1] = float(std::clamp(1.0 - local[k].y / h, 0.0, 1.0));
        }
        // The affine map uv -> output uv: scale, the quarter turn in texel
        // space (uv axes scaled by the atlas's aspect), and the translation
        // that takes the first corner where it went.
        double* m = &result.transforms[6 * size_t(c)];
        if (at.turns) {
            m[0] = 0.0, m[1] = -scale * h / w, m[3] = scale * w / h, m[4] = 0.0;
        } else {
            m[0] = scale, m[1] = 0.0, m[3] = 0.0, m[4] = scale;
        }
        if (!piece.corners.empty()) {
            const glm::dvec2 uv = uvs[size_t(piece.corners[0])];
            m[2] = local[0].x / w - (m[0] * uv.x + m[1] * uv.y);
            m[5] = 1.0 - local[0].y / h - (m[3] * uv.x + m[4] * uv.y);
        }
    }
    if (progress) progress->finish();
    return result;
}

bool first_fit_position(const std::vector<uint8_t>& occupied, int width, int height,
                        const std::vector<uint8_t>& chart, int chart_width, int chart_height, double padding, int& x,
                        int& y, int first_row) {
    pack::Occupancy occupancy(width, height);
    occupancy.place(pack::footprint_of_bits(occupied, width, height, padding), 0, 0);
    return occupancy.first_fit(pack::footprint_of_bits(chart, chart_width, chart_height, padding), x, y, INT32_MAX,
                               first_row);
}

FootprintMasks footprint_masks(const std::vector<uint8_t>& chart, int width, int height, double padding, bool turned) {
    Footprint fp = pack::footprint_of_bits(chart, width, height, padding);
    pack::FootprintScratch scratch;
    if (turned) fp = pack::turned_footprint(fp, scratch);
    FootprintMasks masks;
    masks.width = fp.covered.width;
    masks.height = fp.covered.height;
    masks.reach = fp.reach;
    const auto paint = [](const pack::SpanRows& rows, std::vector<uint8_t>& mask) {
        mask.assign(size_t(rows.width) * size_t(rows.height), 0);
        for (int r = 0; r < rows.height; ++r) {
            const auto row = mask.begin() + int64_t(r) * rows.width;
            for (int k = rows.offsets[size_t(r)]; k < rows.offsets[size_t(r) + 1]; ++k) {
                std::fill(row + rows.spans[size_t(k)].first, row + rows.spans[size_t(k)].second, uint8_t(1));
            }
        }
    };
    paint(fp.covered, masks.covered);
    paint(fp.dilated, masks.dilated);
    return masks;
}

}  // namespace lmrefine
