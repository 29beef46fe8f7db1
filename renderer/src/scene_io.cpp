// load_scene: dispatch from a spec to a reader or the built-in generator.

#include "catgs/scene_io.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string>
#include <string_view>

#include "catgs/builtin_city.hpp"
#include "catgs/scene_ops.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

constexpr std::string_view kBuiltinPrefix = "builtin:";

std::string lower(std::string text) {
    std::transform(text.begin(), text.end(), text.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return text;
}

}  // namespace

namespace {

Scene open_scene(const std::string& spec, const LoadOptions& options, LoadReport* report) {
    if (spec.starts_with(kBuiltinPrefix)) {
        Scene scene = make_city(parse_city_spec(spec), options.progress);
        if (report) *report = LoadReport{.records = scene.count()};
        return scene;
    }
    const std::string extension = lower(std::filesystem::path(spec).extension().string());
    if (extension == ".ply") return read_ply(spec, options, report);
    if (extension == ".splat") return read_splat(spec, options, report);
    io::fail(spec, "unknown scene format; expected a .ply or .splat file or builtin:city",
             extension.empty() ? "no file extension" : "extension " + io::quote(extension));
}

}  // namespace

Scene load_scene(const std::string& spec, const LoadOptions& options, LoadReport* report) {
    Scene scene = open_scene(spec, options, report);
    if (options.chunks) partition_into_chunks(scene);
    return scene;
}

}  // namespace catgs
