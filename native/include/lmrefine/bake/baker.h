// The lightmap baker (docs/method.md §1, step 2): per receiving mesh, or for one
// shared atlas, at a resolution, for each texel its chart covers, the light
// reaching the surface points behind it. Passes match Cycles' DIFFUSE bake
// with the colour pass off (direct, indirect, both) and Cycles' AO bake.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "lmrefine/bake/scene.h"

namespace lmrefine {

class Progress;

enum class BakePass { Direct, AmbientOcclusion, Indirect, Combined };

// "direct", "ao", "indirect", "combined"; InvalidArgument for anything else.
BakePass parse_bake_pass(const std::string& name);
const char* bake_pass_name(BakePass pass);

struct BakeOptions {
    int width = 0, height = 0;
    std::vector<BakePass> passes{BakePass::Direct};
    int samples = 16;          // per texel (or per evaluated point)
    uint64_t seed = 0;
    int bounces = 4;           // diffuse bounces of the indirect pass (Cycles' default)
    float ao_distance = 10.0f; // Blender's world AO distance default
    int dilation = 16;         // texels into the gutter (Blender's default bake margin)
    bool denoise = false;
    bool atlas = false;        // all receivers share one map
};

struct BakeStats {
    uint64_t rays = 0;
    uint64_t texels = 0;  // covered texels (or points) computed
    int64_t degenerate_triangles = 0;  // skipped zero-area triangles of the receivers
    double seconds = 0.0;              // the whole call
    std::vector<std::pair<std::string, double>> pass_seconds;
    double rays_per_second() const;
};

struct BakedMap {
    int mesh = -1;  // receiving mesh id, or -1 for the shared atlas
    std::vector<std::vector<float>> passes;  // per requested pass: (height, width, 4), alpha = coverage
};

struct BakeResult {
    std::vector<BakedMap> maps;
    BakeStats stats;
};

// Bytes a bake will hold at its peak, checked (against physical memory)
// before anything is allocated.
uint64_t bake_memory_estimate(const Scene& scene, const BakeOptions& options);

// Throws InvalidArgument for an empty scene (no receivers; direct or
// combined light with neither lights nor a world), bad options or a
// resolution above 32768; ResourceError when bake_memory_estimate exceeds
// the machine's memory; Cancelled when `progress` was cancelled (nothing
// partial is returned).
BakeResult bake(const Scene& scene, const BakeOptions& options, Progress& progress);

struct EvaluateResult {
    std::vector<std::vector<float>> passes;  // per requested pass: (count, 3)
    BakeStats stats;
};

// The same light at arbitrary surface points with unit `normals` (count, 3)
// (the lit side); options.width/height/dilation/denoise/atlas are ignored.
EvaluateResult evaluate(const Scene& scene, const float* points, const float* normals, int64_t count,
                        const BakeOptions& options, Progress& progress);

}  // namespace lmrefine

namespace lmrefine {

// The benchmark's baseline: a bare loop of rtcOccluded1 over `rays` (count
// rows of origin xyz, direction xyz, tfar) on all threads, against the same
// Embree scene the baker builds. Returns the seconds spent tracing and how
// many rays were occluded.
struct OcclusionLoopResult {
    double seconds = 0.0;
    int64_t occluded = 0;
};
OcclusionLoopResult time_occluded_loop(const Scene& scene, const float* rays, int64_t count);

}  // namespace lmrefine
