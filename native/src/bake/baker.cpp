#include "lmrefine/bake/baker.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "bake_passes.h"
#include "integrator.h"
#include "lmrefine/bake/denoise.h"
#include "lmrefine/bake/dilation.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"
#include "lmrefine/core/parallel.h"
#include "lmrefine/core/progress.h"
#include "lmrefine/layout/coverage.h"
#include "ray_tracer.h"
#include "sampler.h"
#include "texel_table.h"

namespace lmrefine {
namespace {

std::vector<std::vector<int>> map_meshes(const Scene& scene, bool atlas) {
    std::vector<std::vector<int>> maps;
    for (int id = 0; id < int(scene.meshes().size()); ++id) {
        if (!scene.meshes()[size_t(id)].receiver) continue;
        if (atlas && !maps.empty()) {
            maps[0].push_back(id);
        } else {
            maps.push_back({id});
        }
    }
    return maps;
}

// The texel table's candidates past one per texel, for the map that has most
// (maps are baked one at a time), from below: a map whose faces are stacked
// (a texture map taken for a lightmap) needs a (texel, triangle) candidate per
// face and texel; 0 for one whose faces lie side by side.
double stacked_candidates(const Scene& scene, const BakeOptions& options) {
    const double pixels = double(std::max(options.width, 0)) * double(std::max(options.height, 0));
    double most = 0.0;
    for (const auto& map : map_meshes(scene, options.atlas)) {
        double pairs = 0.0;
        for (int id : map) {
            const Mesh& mesh = scene.meshes()[size_t(id)];
            const int64_t count = mesh.triangle_count();
            if (count == 0 || mesh.uvs.size() != size_t(3 * count)) continue;
            std::vector<int32_t> corners(size_t(3 * count));
            std::iota(corners.begin(), corners.end(), 0);
            pairs += texel_pairs_at_least({&mesh.uvs[0].x, 3 * count, corners.data(), count}, options.width,
                                          options.height);
        }
        most = std::max(most, pairs - pixels);
    }
    return most;
}

// Per-texel results of one map while it is baked.
struct MapAccumulator {
    std::vector<float> transport[3];  // (texels * 4) RGB + coverage, per computed transport
    std::vector<float> variance[3];   // (texels) variance of the mean luminance
    std::vector<float> position, normal, texel_size;  // denoise guides
};

float luminance(const glm::vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

struct PixelSums {
    glm::dvec3 sum{0.0};
    double lum = 0.0, lum2 = 0.0;
    void add(const glm::vec3& value) {
        sum += glm::dvec3(value);
        const double l = luminance(value);
        lum += l;
        lum2 += l * l;
    }
    void add(const glm::vec3& value, int64_t times) {  // `times` samples of `value`
        sum += glm::dvec3(value) * double(times);
        const double l = luminance(value);
        lum += l * double(times);
        lum2 += l * l * double(times);
    }
    glm::vec3 mean(int n) const { return glm::vec3(sum / double(n)); }
    float mean_variance(int n) const {
        if (n < 2) return 0.0f;
        const double mean = lum / n;
        return float(std::max(0.0, (lum2 / n - mean * mean) / (n - 1)));
    }
};

void bake_transport(const Scene& scene, const RayTracer& tracer, const Integrator& integrator,
                    const TexelTable& table, int transport, const BakeOptions& options, uint64_t map_key,
                    MapAccumulator& out, std::atomic<uint64_t>& rays, Progress& progress) {
    const int64_t count = int64_t(table.texels.size());
    auto& color = out.transport[transport];
    auto& variance = out.variance[transport];
    color.assign(size_t(count * 4), 0.0f);
    variance.assign(size_t(count), 0.0f);
    const bool guides = out.position.empty();
    if (guides) {
        out.position.assign(size_t(count * 3), 0.0f);
        out.normal.assign(size_t(count * 3), 0.0f);
        out.texel_size.assign(size_t(count), 0.0f);
    }
    parallel_for(count, kItemsPerChunk, [&](int64_t begin, int64_t end) {
        uint64_t local_rays = 0;
        TexelGeometry geometry;
        SampleSequence sequence;
        ShadowBatch batch;
        std::vector<Ray> ao_rays(size_t(options.samples));
        std::vector<uint8_t> ao_blocked(size_t(options.samples));
        std::vector<glm::vec3> sample_values(size_t(options.samples));
        for (int64_t k = begin; k < end; ++k) {
            const int64_t texel = table.texels[size_t(k)];
            const int row = int(texel / table.width), col = int(texel % table.width);
            geometry.load(scene, table, k);
            sequence.reset(hash_combine(map_key, uint64_t(texel)), uint32_t(options.samples),
                           dimension_count(integrator, transport));
            glm::dvec3 position(0.0), normal(0.0);
            batch.clear();
            size_t ao_count = 0;
            for (int s = 0; s < options.samples; ++s) {
                const Sampler sampler(sequence, uint32_t(s));
                const glm::vec2 u = sampler.get(0);
                const SurfacePoint point = geometry.at(col + double(u.x), row + double(u.y));
                if (guides) {
                    position += glm::dvec3(point.position);
                    normal += glm::dvec3(point.shading_normal);
                }
                // Shadow rays are gathered over the texel and traced together;
                // indirect paths depend on their hits and are traced as they go.
                if (transport == kDirect) {
                    integrator.direct_rays(point, sampler, uint32_t(s), batch);
                } else if (transport == kAo) {
                    ao_count += integrator.ao_ray(point, sampler, ao_rays[ao_count]);
                } else {
                    sample_values[size_t(s)] = integrator.indirect(point, sampler, local_rays);
                }
            }
            PixelSums sums;
            if (transport == kAo) {
                tracer.occluded(ao_rays.data(), ao_count, ao_blocked.data());
                local_rays += ao_count;
                int64_t open = 0;
                for (size_t r = 0; r < ao_count; ++r) open += !ao_blocked[r];
                sums.add(glm::vec3(1.0f), open);
            } else {
                if (transport == kDirect) {
                    std::fill(sample_values.begin(), sample_values.end(), glm::vec3(0.0f));
                    batch.blocked.resize(batch.rays.size());
                    tracer.occluded(batch.rays.data(), batch.rays.size(), batch.blocked.data());
                    local_rays += batch.rays.size();
                    for (size_t r = 0; r < batch.rays.size(); ++r) {
                        if (!batch.blocked[r]) sample_values[batch.samples[r]] += batch.values[r];
                    }
                }
                for (const glm::vec3& value : sample_values) sums.add(value);
            }
            const glm::vec3 mean = sums.mean(options.samples);
            for (int ch = 0; ch < 3; ++ch) color[size_t(4 * k + ch)] = mean[ch];
            color[size_t(4 * k + 3)] = 1.0f;
            variance[size_t(k)] = sums.mean_variance(options.samples);
            if (guides) {
                out.texel_size[size_t(k)] = geometry.texel_size();
                const glm::dvec3 p = position / double(options.samples);
                const double length = glm::length(normal);
                const glm::dvec3 n = length > 0.0 ? normal / length : glm::dvec3(0, 0, 1);
                for (int i = 0; i < 3; ++i) {
                    out.position[size_t(3 * k + i)] = float(p[i]);
                    out.normal[size_t(3 * k + i)] = float(n[i]);
                }
            }
        }
        rays.fetch_add(local_rays, std::memory_order_relaxed);
    }, &progress);
    progress.check();
}

// Scatters the covered texels' values into a full (H, W, 4) image and
// finishes it: denoise (optional), then dilation into the gutter.
std::vector<float> finish_map(const TexelTable& table, const MapAccumulator& acc, BakePass pass,
                              const BakeOptions& options) {
    const int64_t count = int64_t(table.texels.size());
    const int64_t pixels = int64_t(table.width) * table.height;
    std::vector<float> image(size_t(pixels * 4), 0.0f), variance(size_t(pixels), 0.0f);
    for (int64_t k = 0; k < count; ++k) {
        const int64_t t = table.texels[size_t(k)];
        image[size_t(4 * t + 3)] = 1.0f;
        for (int tr : kTransports) {
            if (!contributes(pass, tr)) continue;
            for (int ch = 0; ch < 3; ++ch) image[size_t(4 * t + ch)] += acc.transport[tr][size_t(4 * k + ch)];
            variance[size_t(t)] += acc.variance[tr][size_t(k)];
        }
    }
    if (options.denoise) {
        std::vector<uint8_t> covered(size_t(pixels), 0);
        std::vector<float> position(size_t(pixels * 3), 0.0f), normal(size_t(pixels * 3), 0.0f),
            texel_size(size_t(pixels), 0.0f);
        for (int64_t k = 0; k < count; ++k) {
            const int64_t t = table.texels[size_t(k)];
            covered[size_t(t)] = 1;
            texel_size[size_t(t)] = acc.texel_size[size_t(k)];
            for (int i = 0; i < 3; ++i) {
                position[size_t(3 * t + i)] = acc.position[size_t(3 * k + i)];
                normal[size_t(3 * t + i)] = acc.normal[size_t(3 * k + i)];
            }
        }
        const DenoiseGuides guides{table.width, table.height, covered.data(), position.data(), normal.data(),
                                   texel_size.data()};
        denoise(image.data(), variance.data(), guides);
    }
    dilate(image.data(), table.width, table.height, table.texel_chart.data(), table.near_chart.data(),
           options.dilation);
    return image;
}

// bake_memory_estimate with stacked_candidates(scene, options) already counted:
// bake words its refusal with them too, and counting rasterises every map.
uint64_t memory_estimate(const Scene& scene, const BakeOptions& options, double stacked) {
    const uint64_t pixels = uint64_t(std::max(options.width, 0)) * uint64_t(std::max(options.height, 0));
    const uint64_t maps = map_meshes(scene, options.atlas).size();
    const uint64_t transports = uint64_t(needed(options.passes, kDirect)) + needed(options.passes, kAo) +
                                needed(options.passes, kIndirect);
    // Returned images: 16 bytes per texel per pass per map. While one map is
    // baked: its texel table (~40 bytes per texel counting ~1.5 candidates),
    // chart ids (4), the gutter's nearest charts and their distances (8), 20
    // bytes per transport, 28 of guides, and finishing scratch (variance,
    // dilation copies, denoise buffers: ~60).
    const uint64_t returned = maps * uint64_t(options.passes.size()) * pixels * 16;
    const uint64_t working = pixels * (40 + 4 + 8 + 20 * transports + 28 + 60);
    // Stacked faces: ~40 bytes per further candidate (its entry, the table's
    // copy and the stable sort's buffer; 36 measured at 40 quads deep).
    const uint64_t stacked_bytes = uint64_t(std::min(40.0 * stacked, 1e19));
    return returned + working + stacked_bytes;  // stacked_bytes is at most 1e19, the rest far below 2^63
}

}  // namespace

uint64_t bake_memory_estimate(const Scene& scene, const BakeOptions& options) {
    return memory_estimate(scene, options, stacked_candidates(scene, options));
}

BakeResult bake(const Scene& scene, const BakeOptions& options, Progress& progress) {
    const auto started = Clock::now();
    validate_bake_options(scene, options, /*texels=*/true);
    std::string what = "baking at " + std::to_string(options.height) + "x" + std::to_string(options.width);
    std::string advice = "lower the resolution or bake fewer passes or meshes at once";
    const double stacked = stacked_candidates(scene, options);
    if (stacked > 0.0) {
        char depth[32];
        std::snprintf(depth, sizeof depth, "%.3g", 1.0 + stacked / (double(options.width) * options.height));
        what += std::string(" (a lightmap's faces are stacked, at least ") + depth + " deep on average)";
        advice = "give the faces their own places in the lightmap (Lightmap Pack or Smart UV Project), fewer "
                 "stacked faces, or a lower resolution";
    }
    require_memory(what, memory_estimate(scene, options, stacked), advice);
    BakeResult result;
    const RayTracer tracer(scene);
    const IntegratorSettings settings{options.bounces, options.ao_distance};
    const Integrator integrator(scene, tracer, settings);
    std::atomic<uint64_t> rays{0};
    double transport_seconds[3] = {0, 0, 0};
    const auto maps = map_meshes(scene, options.atlas);
    for (size_t m = 0; m < maps.size(); ++m) {
        for (int id : maps[m]) result.stats.degenerate_triangles += scene.meshes()[size_t(id)].degenerate_count;
        const TexelTable table = build_texel_table(scene, maps[m], options.width, options.height);
        result.stats.texels += table.texels.size();
        MapAccumulator acc;
        const uint64_t map_key = hash_combine(options.seed, uint64_t(maps[m].front()));
        const std::string where = maps.size() > 1 ? " (map " + std::to_string(m + 1) + "/" + std::to_string(maps.size()) + ")" : "";
        for (int tr : kTransports) {
            if (!needed(options.passes, tr)) continue;
            const auto pass_started = Clock::now();
            progress.begin(std::string("baking ") + kTransportNames[tr] + where, table.texels.size());
            bake_transport(scene, tracer, integrator, table, tr, options, hash_combine(map_key, uint64_t(tr)), acc,
                           rays, progress);
            progress.finish();
            transport_seconds[tr] += seconds_since(pass_started);
        }
        BakedMap baked;
        baked.mesh = options.atlas ? -1 : maps[m].front();
        for (BakePass pass : options.passes) {
            progress.check();
            baked.passes.push_back(finish_map(table, acc, pass, options));
        }
        result.maps.push_back(std::move(baked));
    }
    for (int tr = 0; tr < 3; ++tr) {
        if (transport_seconds[tr] > 0.0) result.stats.pass_seconds.emplace_back(kTransportNames[tr], transport_seconds[tr]);
    }
    result.stats.rays = rays.load();
    result.stats.seconds = seconds_since(started);
    return result;
}

}  // namespace lmrefine
