// Dilation (docs/method.md §1, step 4): fill the gutter texels next to charts so
// that bilinear sampling at a chart border does not show seams.
#pragma once

#include <cstdint>

namespace lmrefine {

// `texel_chart` (height * width): the chart covering each texel, or -1 in the
// gutter. Each of `iterations` rings gives every gutter texel that touches
// filled texels (8-neighbourhood) the mean colour of its neighbours of one
// chart: the chart with most such neighbours, the smaller id on a tie; the
// texel then belongs to that chart for the next ring. So colour never mixes
// across charts, and covered texels are never written. `rgba` is
// (height, width, 4); colour channels are filled, alpha (coverage) stays 0.
void dilate(float* rgba, int width, int height, const int32_t* texel_chart, int iterations);

}  // namespace lmrefine
