// Edge-aware denoising of a baked lightmap: an a-trous wavelet filter
// (Dammertz et al. 2010) with the edge-stopping weights of SVGF (Schied et
// al. 2017): position (distance from the texel's tangent plane), normal, and
// colour relative to the texels' estimated noise. Texels of different
// surfaces or on either side of a shadow edge barely mix; flat noisy regions
// are smoothed. Only covered texels are read or written.
#pragma once

#include <cstdint>

namespace lmrefine {

struct DenoiseGuides {
    int width = 0, height = 0;
    const uint8_t* covered = nullptr;    // (H * W)
    const float* position = nullptr;     // (H * W * 3) mean world position of the texel's samples
    const float* normal = nullptr;       // (H * W * 3) unit mean shading normal
    const float* texel_size = nullptr;   // (H * W) world-space edge length of a texel
};

// `rgba` (H, W, 4) is filtered in place; `variance` (H * W) is the variance of
// each texel's mean luminance (it is filtered along, and updated).
void denoise(float* rgba, float* variance, const DenoiseGuides& guides, int iterations = 5);

}  // namespace lmrefine
