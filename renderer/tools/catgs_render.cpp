// catgs-render: renders a scene along a camera path to image files and reports per-frame
// times. Exit status: 0 success, 2 bad input (one line on stderr naming the problem),
// 1 any other failure.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "catgs/common/command_line.hpp"
#include "catgs/error.hpp"
#include "catgs/gpu_queues.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/sharded_renderer.hpp"
#include "catgs/trajectory.hpp"
#include "cli_options.hpp"
#include "shard_flags.hpp"
#include "image_file.hpp"

namespace {

struct Options {
    catgs::cli::SceneFlags scene{"builtin:city?gaussians=200000&seed=1"};
    std::string cameras;
    std::string trajectory;
    std::string out;
    std::string format = "png";
    std::string backend = "cpu";
    std::string precision = "float";
    catgs::cli::PipelineFlags pipeline;
    std::string background = "0,0,0";
    int width = 960, height = 540;
    int sh_degree = -1;  // -1: the scene's
    double fov = 70.0;
    double near_plane = catgs::kDefaultNearPlane;
    int threads = 0;
    catgs::cli::ShardFlags sharding;
    long max_frames = -1;
    bool info = false;
    bool json = false;
    bool quiet = false;
};

/// File name for a frame: the camera's name (cameras.json img_name) without extension and
/// directory, else the zero-padded frame index.
std::string frame_file(const catgs::Camera& camera, std::size_t index, const std::string& extension) {
    std::string stem = std::filesystem::path(camera.name).stem().string();
    if (stem.empty() || stem == "." || stem == "..") {
        char buffer[32];
        std::snprintf(buffer, sizeof buffer, "frame_%05zu", index);
        stem = buffer;
    }
    return stem + "." + extension;
}

double percentile(std::vector<double> values, double p) {
    if (values.empty()) return 0;
    std::sort(values.begin(), values.end());
    const double rank = p * static_cast<double>(values.size() - 1);
    const std::size_t lo = static_cast<std::size_t>(rank);
    const std::size_t hi = std::min(lo + 1, values.size() - 1);
    return values[lo] + (rank - static_cast<double>(lo)) * (values[hi] - values[lo]);
}

/// One frame's entry of the --json output; `sharded` adds the shards' part.
nlohmann::json frame_json(std::size_t i, const std::string& file, const catgs::FrameStats& s,
                          const catgs::ShardedFrameStats* sharded) {
    nlohmann::json frame{{"frame", i},
                         {"file", file},
                         {"total_ms", s.total_ms},
                         {"visible", s.visible},
                         {"pairs", s.pairs},
                         {"key_frame", s.key_frame},
                         {"window", s.window},
                         {"split_tasks", s.split_tasks},
                         {"longest_list", s.longest_list},
                         {"occluded", s.occluded},
                         {"occlusion_redrawn", s.occlusion_redrawn}};
    for (catgs::Stage stage : catgs::kStages)
        if (stage != catgs::Stage::encode) frame[std::string(catgs::stage_name(stage)) + "_ms"] = s.stage_ms[stage];
    if (sharded) {
        frame["shard_merge_ms"] = sharded->merge_ms;
        frame["shard_transfer_ms"] = sharded->transfer_ms;
        frame["shard_order"] = sharded->order;
        nlohmann::json per_shard = nlohmann::json::array();
        for (const catgs::FrameStats& part : sharded->shards)
            per_shard.push_back({{"total_ms", part.total_ms}, {"visible", part.visible}, {"pairs", part.pairs}});
        frame["shards"] = std::move(per_shard);
    }
    return frame;
}

/// One frame's line of the text output; `sharded` adds the composite's time.
void print_frame(std::size_t i, const catgs::FrameStats& s, const catgs::ShardedFrameStats* sharded) {
    std::string stages;
    for (catgs::Stage stage : catgs::kStages) {
        if (stage == catgs::Stage::encode) continue;
        char part[64];
        std::snprintf(part, sizeof part, "%s%s %.2f", stages.empty() ? "" : ", ",
                      std::string(catgs::stage_name(stage)).c_str(), s.stage_ms[stage]);
        stages += part;
    }
    char shard_part[64] = "", band_part[32] = "";
    if (sharded) std::snprintf(shard_part, sizeof shard_part, "  shard merge %.2f ms", sharded->merge_ms);
    // Over the renderer's pair budget the frame was drawn in bands of tile rows.
    if (s.bands > 1) std::snprintf(band_part, sizeof band_part, "  bands %d", s.bands);
    std::printf("frame %5zu %s W=%-2d %8.2f ms  (%s)  visible %llu  pairs %llu  splits %llu%s%s\n", i,
                s.key_frame ? "key   " : "cached", s.window, s.total_ms, stages.c_str(),
                static_cast<unsigned long long>(s.visible), static_cast<unsigned long long>(s.pairs),
                static_cast<unsigned long long>(s.split_tasks), band_part, shard_part);
    std::fflush(stdout);
}

int run(const Options& o) {
    const catgs::Precision precision = catgs::parse_precision(o.precision);
    catgs::RenderOptions render_options = catgs::default_pipeline_options();
    catgs::cli::apply_pipeline_flags(o.pipeline, render_options);
    render_options.background = catgs::cli::parse_background(o.background);
    render_options.near_plane = o.near_plane;
    if (!(o.near_plane > 0)) throw catgs::Error("--near must be positive");
    if (o.format != "png" && o.format != "exr") throw catgs::Error("--format '" + o.format + "': expected png or exr");
    if (!o.cameras.empty() && !o.trajectory.empty())
        throw catgs::Error("--cameras and --trajectory are exclusive: give one camera source");

    auto scene = std::make_shared<catgs::Scene>(catgs::cli::load_scene(o.scene, o.quiet));
    if (o.sh_degree >= 0) catgs::truncate_sh(*scene, o.sh_degree);

    if (o.info) {
        if (o.json)
            std::cout << catgs::describe_json(*scene) << "\n";
        else
            std::cout << catgs::describe(*scene) << "\n";
        return 0;
    }

    catgs::Intrinsics intrinsics = catgs::intrinsics_from_fov(o.width, o.height, o.fov);
    catgs::validate(intrinsics, "--width/--height/--fov");
    std::vector<catgs::Camera> cameras;
    if (!o.cameras.empty())
        cameras = catgs::read_cameras_json(o.cameras);
    else
        cameras =
            catgs::load_trajectory(o.trajectory.empty() ? "builtin:survey" : o.trajectory, scene->bounds, intrinsics);
    if (o.max_frames >= 0 && cameras.size() > static_cast<std::size_t>(o.max_frames))
        cameras.resize(static_cast<std::size_t>(o.max_frames));
    if (cameras.empty()) throw catgs::Error("the camera path has no cameras");

    if (!o.out.empty()) {
        std::error_code ec;
        std::filesystem::create_directories(o.out, ec);
        if (ec) throw catgs::Error("--out '" + o.out + "': cannot create directory: " + ec.message());
    }

    // --shards K: one renderer per shard, each holding its shard's Gaussians (sharded_renderer.hpp).
    std::unique_ptr<catgs::Renderer> renderer;
    std::unique_ptr<catgs::ShardedRenderer> sharded =
        catgs::cli::make_sharded_renderer(o.sharding, *scene, o.backend, precision, o.threads);
    if (!sharded) {
        renderer = catgs::make_renderer(o.backend, precision, o.threads);
        renderer->set_scene(scene);
    }
    const std::string renderer_name =
        sharded ? catgs::cli::describe_sharding(o.sharding, *sharded, o.backend) : renderer->name();
    if (!o.json)
        std::cout << "scene: " << catgs::describe(*scene) << "\nrenderer: " << renderer_name << ", "
                  << catgs::cli::describe_pipeline(render_options) << ", " << cameras.size() << " frames\n";

    nlohmann::json frames = nlohmann::json::array();
    std::vector<double> totals;
    catgs::ImageF image;
    catgs::ImageRGB8 image8;
    for (std::size_t i = 0; i < cameras.size(); ++i) {
        // 8-bit frames come straight from render_rgb8: the GPU quantises on the device.
        catgs::FrameStats s;
        catgs::ShardedFrameStats shard_stats;
        if (sharded) {
            shard_stats = o.format == "exr" ? sharded->render(cameras[i], render_options, image)
                                            : sharded->render_rgb8(cameras[i], render_options, image8);
            s = catgs::combine_shard_stats(shard_stats, sharded->concurrent());
        } else {
            s = o.format == "exr" ? renderer->render(cameras[i], render_options, image)
                                  : renderer->render_rgb8(cameras[i], render_options, image8);
        }
        totals.push_back(s.total_ms);
        std::string file;
        if (!o.out.empty()) {
            file = (std::filesystem::path(o.out) / frame_file(cameras[i], i, o.format)).string();
            if (o.format == "exr")
                catgs::write_image(file, image);
            else
                catgs::write_image(file, image8);
        }
        const catgs::ShardedFrameStats* shard_part = sharded ? &shard_stats : nullptr;
        if (o.json)
            frames.push_back(frame_json(i, file, s, shard_part));
        else
            print_frame(i, s, shard_part);
    }
    const double median = percentile(totals, 0.5), p90 = percentile(totals, 0.9),
                 worst = *std::max_element(totals.begin(), totals.end());
    if (o.json) {
        nlohmann::json summary{{"scene", nlohmann::json::parse(catgs::describe_json(*scene))},
                               {"renderer", renderer_name},
                               {"pipeline", catgs::cli::describe_pipeline(render_options)},
                               {"width", cameras[0].intrinsics.width},
                               {"height", cameras[0].intrinsics.height},
                               {"frames", frames},
                               {"median_ms", median},
                               {"p90_ms", p90},
                               {"max_ms", worst}};
        std::cout << summary.dump(2) << "\n";
    } else {
        std::printf("summary: %zu frames, median %.2f ms, p90 %.2f ms, max %.2f ms (%.1f fps at the median)%s%s\n",
                    totals.size(), median, p90, worst, median > 0 ? 1000.0 / median : 0.0,
                    o.out.empty() ? "" : ", frames in ", o.out.c_str());
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    catgs::request_gpu_hardware_queues();
    Options o;
    CLI::App app{"catgs-render: render a 3D Gaussian Splatting scene along a camera path"};
    catgs::cli::add_scene_flags(app, o.scene);
    app.add_option("--cameras", o.cameras, "graphdeco cameras.json (uses its own intrinsics)");
    app.add_option("--trajectory", o.trajectory,
                   "trajectory file, or builtin:survey|orbit|flythrough|hover?speed=&fps=&altitude=&pitch=&frames= "
                   "(default builtin:survey)");
    app.add_option("--out", o.out, "directory for one image per camera (named after img_name or the frame index)");
    app.add_option("--format", o.format, "png (8-bit) or exr (float, unclamped)")->capture_default_str();
    app.add_option("--backend", o.backend, "cpu or cuda (" + catgs::available_backends() + " built in)")
        ->capture_default_str();
    app.add_option("--precision", o.precision, "float or double")->capture_default_str();
    catgs::cli::add_pipeline_flags(app, o.pipeline);
    app.add_option("--background", o.background, "background colour r,g,b in [0,1]")->capture_default_str();
    app.add_option("--width", o.width, "image width for trajectories")
        ->capture_default_str()
        ->check(catgs::image_side());
    app.add_option("--height", o.height, "image height for trajectories")
        ->capture_default_str()
        ->check(catgs::image_side());
    app.add_option("--fov", o.fov, "horizontal field of view in degrees for trajectories")
        ->capture_default_str()
        ->check(catgs::horizontal_fov());
    app.add_option("--near", o.near_plane, "near plane (view-space z)")->capture_default_str();
    app.add_option("--threads", o.threads, "CPU threads (0: all)")->check(catgs::thread_count())->capture_default_str();
    catgs::cli::add_shard_flags(app, o.sharding);
    app.add_option("--max-frames", o.max_frames, "render at most this many cameras (-1: all)")->capture_default_str();
    app.add_option("--sh-degree", o.sh_degree,
                   "render with the SH coefficients above this degree (0..3) dropped; 0: view-independent colour "
                   "(default: the scene's degree)")
        ->check(CLI::Range(0, 3));
    app.add_flag("--info", o.info, "print the scene's count, SH degree, bounds and memory, then exit");
    app.add_flag("--json", o.json, "machine-readable output (--info, or the render summary with per-frame stats)");
    app.add_flag("--quiet", o.quiet, "no progress output on stderr");
    return catgs::run_command_line(app, argc, argv, "catgs-render", [&] { return run(o); });
}
