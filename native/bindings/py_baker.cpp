// The native half of lmrefine.bake / lmrefine.evaluate (python/lmrefine/baker.py
// holds the documented Python API and shapes the results).
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <limits>
#include <string>
#include <vector>

#include "lmrefine/bake/baker.h"
#include "lmrefine/bake/dilation.h"
#include "lmrefine/core/error.h"
#include "lmrefine/core/memory.h"
#include "numpy_util.h"
#include "progress_binding.h"

namespace py = pybind11;

namespace lmrefine::bindings {
namespace {

// The numbers arrive as Python objects: a float, None or a str is a
// TypeError and an out-of-range int a ValueError naming the argument, never
// a failed cast.
BakeOptions make_options(const std::vector<std::string>& passes, const py::handle& samples, const py::handle& seed,
                         const py::handle& bounces, const py::handle& ao_distance) {
    BakeOptions options;
    options.passes.clear();
    for (const auto& name : passes) options.passes.push_back(parse_bake_pass(name));
    options.samples = int(py_util::int_param(samples, "samples", 1, 1 << 20));
    options.seed = uint64_t(py_util::int_param(seed, "seed", 0, std::numeric_limits<int64_t>::max()));
    options.bounces = int(py_util::int_param(bounces, "bounces", 0, 64));
    options.ao_distance = float(py_util::real_param(ao_distance, "ao_distance"));
    return options;
}

py::dict stats_dict(const BakeStats& stats) {
    py::dict seconds;
    for (const auto& p : stats.pass_seconds) seconds[py::str(p.first)] = p.second;
    py::dict d;
    d["rays"] = stats.rays;
    d["rays_per_second"] = stats.rays_per_second();
    d["seconds"] = stats.seconds;
    d["pass_seconds"] = seconds;
    d["texels"] = stats.texels;
    d["degenerate_triangles"] = stats.degenerate_triangles;
    return d;
}

py::tuple bake_native(const Scene& scene, const py::handle& resolution, const std::vector<std::string>& passes,
                      const py::handle& samples, const py::handle& seed, const py::object& progress,
                      const py::handle& dilation, bool denoise, const py::handle& bounces,
                      const py::handle& ao_distance, bool atlas) {
    BakeOptions options = make_options(passes, samples, seed, bounces, ao_distance);
    std::tie(options.height, options.width) = py_util::parse_resolution(resolution, "baking", 0);
    options.dilation = int(py_util::int_param(dilation, "dilation", 0, 1 << 24));
    options.denoise = denoise;
    options.atlas = atlas;
    py_util::PythonProgress reporter(progress);
    const Scene::Reading reading(scene);
    BakeResult result = reporter.run([&](Progress& p) { return bake(scene, options, p); });
    py::list maps;
    for (auto& map : result.maps) {
        py::list images;
        for (auto& image : map.passes) {
            images.append(py_util::to_numpy(std::move(image), {options.height, options.width, 4}));
        }
        maps.append(py::make_tuple(map.mesh, images));
    }
    return py::make_tuple(maps, stats_dict(result.stats));
}

py::tuple evaluate_native(const Scene& scene, const py::handle& points_in, const py::handle& normals_in,
                          const std::vector<std::string>& passes, const py::handle& samples, const py::handle& seed,
                          const py::object& progress, const py::handle& bounces, const py::handle& ao_distance) {
    auto points = py_util::require_points(points_in, "points", 3);
    auto normals = py_util::require_points(normals_in, "normals", 3);
    if (normals.shape(0) != points.shape(0)) {
        throw py::value_error("normals must have one row per point: " + py_util::shape_string(points) + " points, " +
                              py_util::shape_string(normals) + " normals");
    }
    const BakeOptions options = make_options(passes, samples, seed, bounces, ao_distance);
    py_util::PythonProgress reporter(progress);
    const Scene::Reading reading(scene);
    const int64_t count = points.shape(0);
    EvaluateResult result =
        reporter.run([&](Progress& p) { return evaluate(scene, points.data(), normals.data(), count, options, p); });
    py::list values;
    for (auto& v : result.passes) values.append(py_util::to_numpy(std::move(v), {py::ssize_t(count), 3}));
    return py::make_tuple(values, stats_dict(result.stats));
}

// The baker's dilation for an image baked elsewhere: a new float32 array of the
// image's shape, its colour channels refilled in the gutter, alpha as given.
py::array_t<float> dilate_native(const py::handle& image_in, const py::handle& uvs_in, const py::handle& triangles_in,
                                 const py::handle& texels) {
    auto image = py_util::require_float32(image_in, "image", {3});
    const int64_t height = image.shape(0), width = image.shape(1), channels = image.shape(2);
    if (channels != 3 && channels != 4) {
        throw py::value_error("image must have shape (H, W, 3) or (H, W, 4), got " + py_util::shape_string(image));
    }
    if (height > (1 << 15) || width > (1 << 15)) {
        throw py::value_error("image is larger than 32768 texels a side: shape " + py_util::shape_string(image));
    }
    auto uvs = py_util::require_points(uvs_in, "uvs", 2);
    auto triangles = py_util::require_indices(triangles_in, "triangles", 3, /*allow_empty=*/true);
    const int iterations = int(py_util::int_param(texels, "texels", 0, 1 << 15));
    const UvLayout layout{uvs.data(), uvs.shape(0), triangles.data(), triangles.shape(0)};
    const int64_t pixels = height * width;
    require_memory("dilating a " + std::to_string(height) + "x" + std::to_string(width) + " image",
                   saturating_product({uint64_t(pixels), uint64_t(16 + 4 * channels + 20)}), "dilate a smaller image");
    std::vector<float> out(image.data(), image.data() + pixels * channels);
    {
        py::gil_scoped_release release;
        validate_layout(layout);
        std::vector<float> rgba(size_t(pixels * 4), 0.0f);
        for (int64_t i = 0; i < pixels; ++i) {
            for (int ch = 0; ch < 3; ++ch) rgba[size_t(4 * i + ch)] = out[size_t(channels * i + ch)];
        }
        dilate(rgba.data(), int(width), int(height), layout, iterations);
        for (int64_t i = 0; i < pixels; ++i) {
            for (int ch = 0; ch < 3; ++ch) out[size_t(channels * i + ch)] = rgba[size_t(4 * i + ch)];
        }
    }
    return py_util::to_numpy(std::move(out), {py::ssize_t(height), py::ssize_t(width), py::ssize_t(channels)});
}

}  // namespace

void bind_baker(py::module_& m) {
    m.def("_bake", &bake_native, py::arg("scene"), py::arg("resolution"), py::arg("passes"), py::arg("samples"),
          py::arg("seed"), py::arg("progress"), py::arg("dilation"), py::arg("denoise"), py::arg("bounces"),
          py::arg("ao_distance"), py::arg("atlas"),
          "Native bake: returns ([(mesh id or -1, [image per pass])], stats). Use lmrefine.bake.");
    m.def("_evaluate", &evaluate_native, py::arg("scene"), py::arg("points"), py::arg("normals"), py::arg("passes"),
          py::arg("samples"), py::arg("seed"), py::arg("progress"), py::arg("bounces"), py::arg("ao_distance"),
          "Native evaluate: returns ([(P, 3) per pass], stats). Use lmrefine.evaluate.");
    m.def("_dilate", &dilate_native, py::arg("image"), py::arg("uvs"), py::arg("triangles"), py::arg("texels"),
          "Native dilation of an image baked elsewhere. Use lmrefine.dilate.");
    m.def(
        "_bench_occluded_loop",
        [](const Scene& scene, const py::handle& rays_in) {
            auto rays = py_util::require_points(rays_in, "rays", 7);
            const int64_t count = rays.shape(0);
            OcclusionLoopResult result;
            {
                const Scene::Reading reading(scene);
                py::gil_scoped_release release;
                result = time_occluded_loop(scene, rays.data(), count);
            }
            return py::make_tuple(result.seconds, result.occluded);
        },
        py::arg("scene"), py::arg("rays"),
        "Benchmark baseline: a bare rtcOccluded1 loop over rays (N, 7) = origin, direction, tfar on all threads; "
        "returns (seconds, occluded count).");
}

}  // namespace lmrefine::bindings
