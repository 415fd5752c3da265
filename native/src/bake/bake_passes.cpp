#include "bake_passes.h"

#include <cmath>
#include <string>

#include "lmrefine/core/error.h"
#include "lmrefine/bake/scene.h"

namespace lmrefine {
namespace {

constexpr int kMaxResolution = 32768;

}  // namespace

void validate_bake_options(const Scene& scene, const BakeOptions& options, bool texels) {
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

}  // namespace lmrefine
