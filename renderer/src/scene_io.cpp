// load_scene: dispatch from a spec to a reader or the built-in generator.

#include "catgs/scene_io.hpp"

#include <string>
#include <string_view>

#include "catgs/builtin_city.hpp"
#include "catgs/scene_format.hpp"
#include "catgs/scene_ops.hpp"
#include "scene_io_detail.hpp"

namespace catgs {

namespace {

constexpr std::string_view kBuiltinPrefix = "builtin:";

}  // namespace

namespace {

Scene open_scene(const std::string& spec, const LoadOptions& options, LoadReport* report) {
    if (spec.starts_with(kBuiltinPrefix)) {
        Scene scene = make_city(parse_city_spec(spec), options.progress);
        if (report) *report = LoadReport{.records = scene.count()};
        return scene;
    }
    return read_scene_file(spec, options, report);
}

}  // namespace

Scene load_scene(const std::string& spec, const LoadOptions& options, LoadReport* report) {
    Scene scene = open_scene(spec, options, report);
    if (options.chunks) partition_into_chunks(scene);
    return scene;
}

}  // namespace catgs
