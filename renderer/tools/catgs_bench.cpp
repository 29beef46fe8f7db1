// catgs-bench: renders a camera path and reports per-stage times (CUDA events on the GPU),
// tile-Gaussian pairs, visible Gaussians and arena memory per frame, with median, p90 and max.
// It links no OpenImageIO, so it runs on bare GPU hosts (see deploy/bundle.sh).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>

#include "catgs/error.hpp"
#include "catgs/renderer.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/scene_ops.hpp"
#include "catgs/trajectory.hpp"

namespace {

constexpr int kExitBadInput = 2;
constexpr int kExitFailure = 1;

struct Options {
    std::string scene = "builtin:city?gaussians=1000000&seed=1";
    std::string grid = "1x1";
    std::string up = "z";
    std::string trajectory = "builtin:survey?altitude=80&pitch=-45&speed=8&fps=30&frames=300";
    std::string backend = "cuda";
    std::string precision = "float";
    std::string culling = "opacity-aware";
    std::string json_out;
    int width = 1920, height = 1080;
    double fov = 70.0;
    int warmup = 5;
    long max_frames = -1;
    int threads = 0;
    bool quiet = false;
};

struct Series {
    std::vector<double> values;
    double percentile(double p) const {
        if (values.empty()) return 0;
        std::vector<double> v = values;
        std::sort(v.begin(), v.end());
        const double rank = p * static_cast<double>(v.size() - 1);
        const auto lo = static_cast<std::size_t>(rank);
        const std::size_t hi = std::min(lo + 1, v.size() - 1);
        return v[lo] + (rank - static_cast<double>(lo)) * (v[hi] - v[lo]);
    }
    double max() const { return values.empty() ? 0 : *std::max_element(values.begin(), values.end()); }
};

int run(const Options& o) {
    catgs::RenderOptions render_options;
    render_options.culling = catgs::parse_culling(o.culling);
    const catgs::Precision precision = catgs::parse_precision(o.precision);
    const auto [grid_x, grid_y] = catgs::parse_grid(o.grid);
    const int up_axis = catgs::parse_up_axis(o.up);
    if (o.warmup < 0) throw catgs::Error("--warmup must be >= 0");

    catgs::LoadOptions load;
    load.progress = catgs::stderr_progress(!o.quiet);
    auto scene = std::make_shared<catgs::Scene>(catgs::load_scene(o.scene, load));
    if (grid_x * grid_y > 1) *scene = catgs::replicate_grid(*scene, grid_x, grid_y, up_axis);

    const catgs::Intrinsics intrinsics = catgs::intrinsics_from_fov(o.width, o.height, o.fov);
    catgs::validate(intrinsics, "--width/--height/--fov");
    std::vector<catgs::Camera> cameras = catgs::load_trajectory(o.trajectory, scene->bounds, intrinsics);
    if (o.max_frames >= 0 && cameras.size() > static_cast<std::size_t>(o.max_frames))
        cameras.resize(static_cast<std::size_t>(o.max_frames));
    if (cameras.empty()) throw catgs::Error("the camera path has no cameras");

    auto renderer = catgs::make_renderer(o.backend, precision, o.threads);
    renderer->set_scene(scene);
    std::printf("scene: %s\nrenderer: %s, culling %s, %dx%d, %zu frames, %d warm-up renders\n",
                catgs::describe(*scene).c_str(), renderer->name().c_str(), catgs::culling_name(render_options.culling),
                cameras[0].intrinsics.width, cameras[0].intrinsics.height, cameras.size(), o.warmup);
    std::fflush(stdout);

    catgs::ImageRGB8 image;
    for (int i = 0; i < o.warmup; ++i) renderer->render_rgb8(cameras[0], render_options, image);

    const char* stage_names[] = {"preprocess", "scan", "emit", "sort", "ranges", "rasterize", "copy", "total"};
    std::vector<Series> stages(8);
    Series pairs, visible, arena;
    nlohmann::json frames = nlohmann::json::array();
    for (std::size_t f = 0; f < cameras.size(); ++f) {
        const catgs::FrameStats s = renderer->render_rgb8(cameras[f], render_options, image);
        const double values[] = {s.preprocess_ms, s.scan_ms, s.keys_ms, s.sort_ms, s.ranges_ms, s.rasterize_ms,
                                 s.copy_ms, s.total_ms};
        for (int k = 0; k < 8; ++k) stages[k].values.push_back(values[k]);
        pairs.values.push_back(static_cast<double>(s.pairs));
        visible.values.push_back(static_cast<double>(s.visible));
        arena.values.push_back(static_cast<double>(s.arena_bytes));
        nlohmann::json frame{{"frame", f}, {"pairs", s.pairs}, {"visible", s.visible}, {"arena_bytes", s.arena_bytes},
                             {"bands", s.bands}};
        for (int k = 0; k < 8; ++k) frame[std::string(stage_names[k]) + "_ms"] = values[k];
        frames.push_back(frame);
        if (!o.quiet && (f + 1) % std::max<std::size_t>(1, cameras.size() / 10) == 0)
            std::fprintf(stderr, "benchmark: %zu/%zu frames\n", f + 1, cameras.size());
    }

    std::printf("\n%-12s %10s %10s %10s\n", "stage (ms)", "median", "p90", "max");
    nlohmann::json summary;
    for (int k = 0; k < 8; ++k) {
        std::printf("%-12s %10.3f %10.3f %10.3f\n", stage_names[k], stages[k].percentile(0.5), stages[k].percentile(0.9),
                    stages[k].max());
        summary[stage_names[k]] = {{"median_ms", stages[k].percentile(0.5)},
                                   {"p90_ms", stages[k].percentile(0.9)},
                                   {"max_ms", stages[k].max()}};
    }
    std::printf("%-12s %10.0f %10.0f %10.0f\n", "pairs", pairs.percentile(0.5), pairs.percentile(0.9), pairs.max());
    std::printf("%-12s %10.0f %10.0f %10.0f\n", "visible", visible.percentile(0.5), visible.percentile(0.9),
                visible.max());
    std::printf("%-12s %10.1f %10.1f %10.1f\n", "arena MiB", arena.percentile(0.5) / 1048576.0,
                arena.percentile(0.9) / 1048576.0, arena.max() / 1048576.0);
    summary["pairs"] = {{"median", pairs.percentile(0.5)}, {"p90", pairs.percentile(0.9)}, {"max", pairs.max()}};
    summary["visible"] = {{"median", visible.percentile(0.5)}, {"p90", visible.percentile(0.9)}, {"max", visible.max()}};
    summary["peak_arena_bytes"] = arena.max();

    if (!o.json_out.empty()) {
        nlohmann::json doc{{"scene", nlohmann::json::parse(catgs::describe_json(*scene))},
                           {"scene_spec", o.scene},
                           {"grid", o.grid},
                           {"trajectory", o.trajectory},
                           {"renderer", renderer->name()},
                           {"culling", catgs::culling_name(render_options.culling)},
                           {"width", cameras[0].intrinsics.width},
                           {"height", cameras[0].intrinsics.height},
                           {"warmup", o.warmup},
                           {"summary", summary},
                           {"frames", frames}};
        std::ofstream out(o.json_out);
        if (!out) throw catgs::Error("--json-out '" + o.json_out + "': cannot open for writing");
        out << doc.dump(2) << "\n";
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    CLI::App app{"catgs-bench: per-stage timings of a renderer along a camera path"};
    app.add_option("--scene", o.scene, "PLY or .splat file, or builtin:city?gaussians=N&seed=S")->capture_default_str();
    app.add_option("--grid", o.grid, "replicate the scene NxM over the horizontal axes (e.g. 3x3)")->capture_default_str();
    app.add_option("--up", o.up, "the scene's up axis (x, y, z, -y, ...) for --grid")->capture_default_str();
    app.add_option("--trajectory", o.trajectory, "trajectory file or builtin:survey|orbit|flythrough|hover?...")
        ->capture_default_str();
    app.add_option("--backend", o.backend, "cpu or cuda (" + catgs::available_backends() + " built in)")
        ->capture_default_str();
    app.add_option("--precision", o.precision, "float or double")->capture_default_str();
    app.add_option("--culling", o.culling, "exact, bbox3sigma or opacity-aware")->capture_default_str();
    app.add_option("--width", o.width, "image width")->capture_default_str();
    app.add_option("--height", o.height, "image height")->capture_default_str();
    app.add_option("--fov", o.fov, "horizontal field of view in degrees")->capture_default_str();
    app.add_option("--warmup", o.warmup, "untimed renders of the first camera before timing")->capture_default_str();
    app.add_option("--max-frames", o.max_frames, "time at most this many cameras (-1: all)")->capture_default_str();
    app.add_option("--threads", o.threads, "CPU threads for the cpu backend (0: all)")->capture_default_str();
    app.add_option("--json-out", o.json_out, "write per-frame and summary results as JSON to this file");
    app.add_flag("--quiet", o.quiet, "no progress output on stderr");
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::cerr << "catgs-bench: " << e.what() << "\n";
        return kExitBadInput;
    }
    try {
        return run(o);
    } catch (const catgs::Error& e) {
        std::cerr << "catgs-bench: " << e.what() << "\n";
        return kExitBadInput;
    } catch (const std::exception& e) {
        std::cerr << "catgs-bench: failed: " << e.what() << "\n";
        return kExitFailure;
    }
}
