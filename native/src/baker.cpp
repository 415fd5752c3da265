#include "lmrefine/baker.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <string>

#include <glm/geometric.hpp>

#include "integrator.h"
#include "lmrefine/denoise.h"
#include "lmrefine/dilation.h"
#include "lmrefine/error.h"
#include "lmrefine/parallel.h"
#include "lmrefine/progress.h"
#include "ray_tracer.h"
#include "sampler.h"
#include "texel_table.h"

namespace lmrefine {
namespace {

constexpr int kMaxResolution = 32768;
constexpr int64_t kTexelsPerChunk = 64;

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

// A pass is made of light transports, each computed once per bake.
enum Transport { kDirect = 0, kAo = 1, kIndirect = 2 };
const char* const kTransportNames[3] = {"direct", "ao", "indirect"};
constexpr int kTransports[3] = {kDirect, kAo, kIndirect};

// Whether a transport is part of a requested pass (combined = direct + indirect).
bool contributes(BakePass pass, int transport) {
    switch (transport) {
        case kDirect: return pass == BakePass::Direct || pass == BakePass::Combined;
        case kIndirect: return pass == BakePass::Indirect || pass == BakePass::Combined;
        default: return pass == BakePass::AmbientOcclusion;
    }
}

bool needed(const std::vector<BakePass>& passes, int transport) {
    return std::any_of(passes.begin(), passes.end(), [&](BakePass p) { return contributes(p, transport); });
}

void validate(const Scene& scene, const BakeOptions& options, bool texels) {
    LMREFINE_REQUIRE(!options.passes.empty(), "passes is empty; ask for one of \"direct\", \"ao\", \"indirect\", \"combined\"");
    LMREFINE_REQUIRE(options.samples >= 1 && options.samples <= (1 << 20), "samples must be in [1, 1048576]");
    LMREFINE_REQUIRE(options.bounces >= 0 && options.bounces <= 64, "bounces must be in [0, 64]");
    LMREFINE_REQUIRE(std::isfinite(options.ao_distance) && options.ao_distance > 0.0f, "ao_distance must be > 0");
    if (needed(options.passes, kDirect) || needed(options.passes, kIndirect)) {
        LMREFINE_REQUIRE(!scene.lights().empty() || scene.has_world(),
                         "the scene has no lights and no world colour, so direct and indirect light are zero; "
                         "add a light (Scene.add_light) or a sky (Scene.set_world)");
    }
    if (!texels) return;
    LMREFINE_REQUIRE(options.dilation >= 0, "dilation must be >= 0 texels");
    LMREFINE_REQUIRE(options.width >= 1 && options.height >= 1, "resolution must be positive");
    LMREFINE_REQUIRE(options.width <= kMaxResolution && options.height <= kMaxResolution,
                     "resolution " + std::to_string(options.height) + "x" + std::to_string(options.width) +
                         " is above the largest lightmap, " + std::to_string(kMaxResolution) + "x" +
                         std::to_string(kMaxResolution));
    bool receivers = false;
    for (const Mesh& mesh : scene.meshes()) receivers |= mesh.receiver;
    LMREFINE_REQUIRE(receivers, "the scene has no receiving mesh, so there is no lightmap to bake; "
                                "add a mesh with lightmap uvs and receiver=True");
}

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

uint64_t physical_memory() {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
    return pages > 0 && page > 0 ? uint64_t(pages) * uint64_t(page) : (uint64_t(1) << 34);
}

std::string gib(uint64_t bytes) {
    char text[32];
    std::snprintf(text, sizeof text, "%.2f GiB", double(bytes) / double(uint64_t(1) << 30));
    return text;
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
    glm::vec3 mean(int n) const { return glm::vec3(sum / double(n)); }
    float mean_variance(int n) const {
        if (n < 2) return 0.0f;
        const double mean = lum / n;
        return float(std::max(0.0, (lum2 / n - mean * mean) / (n - 1)));
    }
};

glm::vec3 estimate(const Integrator& integrator, int transport, const SurfacePoint& point, const Sampler& sampler,
                   uint64_t& rays) {
    switch (transport) {
        case kDirect: return integrator.direct(point, sampler, 0, rays);
        case kAo: return glm::vec3(integrator.ambient_occlusion(point, sampler, rays));
        default: return integrator.indirect(point, sampler, rays);
    }
}

void bake_transport(const Scene& scene, const Integrator& integrator, const TexelTable& table, int transport,
                    const BakeOptions& options, uint64_t map_key, MapAccumulator& out, std::atomic<uint64_t>& rays,
                    Progress& progress) {
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
    parallel_for(count, kTexelsPerChunk, [&](int64_t begin, int64_t end) {
        uint64_t local_rays = 0;
        TexelGeometry geometry;
        SampleSequence sequence;
        for (int64_t k = begin; k < end; ++k) {
            const int64_t texel = table.texels[size_t(k)];
            const int row = int(texel / table.width), col = int(texel % table.width);
            geometry.load(scene, table, k);
            sequence.reset(hash_combine(map_key, uint64_t(texel)), uint32_t(options.samples),
                           integrator.dimension_count());
            PixelSums sums;
            glm::dvec3 position(0.0), normal(0.0);
            for (int s = 0; s < options.samples; ++s) {
                const Sampler sampler(sequence, uint32_t(s));
                const glm::vec2 u = sampler.get(0);
                const SurfacePoint point = geometry.at(col + double(u.x), row + double(u.y));
                if (guides) {
                    position += glm::dvec3(point.position);
                    normal += glm::dvec3(point.shading_normal);
                }
                sums.add(estimate(integrator, transport, point, sampler, local_rays));
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
    dilate(image.data(), table.width, table.height, table.texel_chart.data(), options.dilation);
    return image;
}

}  // namespace

BakePass parse_bake_pass(const std::string& name) {
    if (name == "direct") return BakePass::Direct;
    if (name == "ao") return BakePass::AmbientOcclusion;
    if (name == "indirect") return BakePass::Indirect;
    if (name == "combined") return BakePass::Combined;
    LMREFINE_THROW(InvalidArgument, "unknown pass \"" + name + "\"; use \"direct\", \"ao\", \"indirect\" or \"combined\"");
}

const char* bake_pass_name(BakePass pass) {
    switch (pass) {
        case BakePass::Direct: return "direct";
        case BakePass::AmbientOcclusion: return "ao";
        case BakePass::Indirect: return "indirect";
        case BakePass::Combined: return "combined";
    }
    return "?";
}

double BakeStats::rays_per_second() const {
    double traced = 0.0;
    for (const auto& p : pass_seconds) traced += p.second;
    return traced > 0.0 ? double(rays) / traced : 0.0;
}

uint64_t bake_memory_estimate(const Scene& scene, const BakeOptions& options) {
    const uint64_t pixels = uint64_t(std::max(options.width, 0)) * uint64_t(std::max(options.height, 0));
    const uint64_t maps = map_meshes(scene, options.atlas).size();
    const uint64_t transports = uint64_t(needed(options.passes, kDirect)) + needed(options.passes, kAo) +
                                needed(options.passes, kIndirect);
    // Returned images: 16 bytes per texel per pass per map. While one map is
    // baked: its texel table (~40 bytes per texel counting ~1.5 candidates),
    // chart ids (4), 20 bytes per transport, 28 of guides, and finishing
    // scratch (variance, dilation copies, denoise buffers: ~60).
    const uint64_t returned = maps * uint64_t(options.passes.size()) * pixels * 16;
    const uint64_t working = pixels * (40 + 4 + 20 * transports + 28 + 60);
    return returned + working;
}

BakeResult bake(const Scene& scene, const BakeOptions& options, Progress& progress) {
    const auto started = Clock::now();
    validate(scene, options, /*texels=*/true);
    const uint64_t required = bake_memory_estimate(scene, options), available = physical_memory();
    if (required > available / 2) {
        LMREFINE_THROW(ResourceError, "baking at " + std::to_string(options.height) + "x" +
                                          std::to_string(options.width) + " needs about " + gib(required) +
                                          " of memory, more than half of this machine's " + gib(available) +
                                          "; lower the resolution or bake fewer passes or meshes at once");
    }
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
            bake_transport(scene, integrator, table, tr, options, hash_combine(map_key, uint64_t(tr)), acc, rays, progress);
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

EvaluateResult evaluate(const Scene& scene, const float* points, const float* normals, int64_t count,
                        const BakeOptions& options, Progress& progress) {
    const auto started = Clock::now();
    validate(scene, options, /*texels=*/false);
    std::vector<SurfacePoint> surface(static_cast<size_t>(count));
    for (int64_t i = 0; i < count; ++i) {
        const glm::vec3 p(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
        const glm::vec3 n(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]);
        const float length = glm::length(n);
        LMREFINE_REQUIRE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z),
                         "points[" + std::to_string(i) + "] is NaN or Inf");
        LMREFINE_REQUIRE(std::isfinite(length) && length > 0.0f,
                         "normals[" + std::to_string(i) + "] is zero, NaN or Inf; pass the unit normal of the lit side");
        surface[size_t(i)] = {p, n / length, n / length};
    }
    EvaluateResult result;
    const RayTracer tracer(scene);
    const Integrator integrator(scene, tracer, IntegratorSettings{options.bounces, options.ao_distance});
    std::vector<float> transport[3];
    std::atomic<uint64_t> rays{0};
    for (int tr : kTransports) {
        if (!needed(options.passes, tr)) continue;
        const auto pass_started = Clock::now();
        transport[tr].assign(size_t(count * 3), 0.0f);
        const uint64_t key = hash_combine(hash_combine(options.seed, 0x6576616cull), uint64_t(tr));
        progress.begin(std::string("evaluating ") + kTransportNames[tr], uint64_t(count));
        parallel_for(count, kTexelsPerChunk, [&](int64_t begin, int64_t end) {
            uint64_t local_rays = 0;
            SampleSequence sequence;
            for (int64_t i = begin; i < end; ++i) {
                glm::dvec3 sum(0.0);
                sequence.reset(hash_combine(key, uint64_t(i)), uint32_t(options.samples), integrator.dimension_count());
                for (int s = 0; s < options.samples; ++s) {
                    const Sampler sampler(sequence, uint32_t(s));
                    sum += glm::dvec3(estimate(integrator, tr, surface[size_t(i)], sampler, local_rays));
                }
                for (int ch = 0; ch < 3; ++ch) transport[tr][size_t(3 * i + ch)] = float(sum[ch] / options.samples);
            }
            rays.fetch_add(local_rays, std::memory_order_relaxed);
        }, &progress);
        progress.check();
        progress.finish();
        result.stats.pass_seconds.emplace_back(kTransportNames[tr], seconds_since(pass_started));
    }
    for (BakePass pass : options.passes) {
        std::vector<float> values(size_t(count * 3), 0.0f);
        for (int tr : kTransports) {
            if (!contributes(pass, tr)) continue;
            for (size_t i = 0; i < values.size(); ++i) values[i] += transport[tr][i];
        }
        result.passes.push_back(std::move(values));
    }
    result.stats.rays = rays.load();
    result.stats.texels = uint64_t(count);
    result.stats.seconds = seconds_since(started);
    return result;
}

}  // namespace lmrefine

namespace lmrefine {

OcclusionLoopResult time_occluded_loop(const Scene& scene, const float* rays, int64_t count) {
    const RayTracer tracer(scene);
    std::atomic<int64_t> occluded{0};
    const auto started = Clock::now();
    parallel_for(count, 4096, [&](int64_t begin, int64_t end) {
        occluded.fetch_add(tracer.occluded_batch(rays, begin, end), std::memory_order_relaxed);
    });
    return {seconds_since(started), occluded.load()};
}

}  // namespace lmrefine
