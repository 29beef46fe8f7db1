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
#include "cli_options.hpp"

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
    catgs::cli::PipelineFlags pipeline;
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
    catgs::cli::apply_pipeline_flags(o.pipeline, render_options);
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
    std::printf("scene: %s\nrenderer: %s, %s, %dx%d, %zu frames, %d warm-up renders\n",
                catgs::describe(*scene).c_str(), renderer->name().c_str(),
                catgs::cli::describe_pipeline(render_options).c_str(), cameras[0].intrinsics.width,
                cameras[0].intrinsics.height, cameras.size(), o.warmup);
    std::fflush(stdout);

    // Warm-up renders of the first camera, then a fresh cache so the timed path starts cold.
    catgs::ImageRGB8 image;
    for (int i = 0; i < o.warmup; ++i) renderer->render_rgb8(cameras[0], render_options, image);
    renderer->reset_cache();

    constexpr int kStages = 10;
    const char* stage_names[kStages] = {"preprocess", "scan",      "emit",  "sort", "ranges",
                                        "split",      "rasterize", "merge", "copy", "total"};
    std::vector<Series> stages(kStages);
    Series pairs, visible, arena, key_total, cached_total, window, splits;
    nlohmann::json frames = nlohmann::json::array();
    for (std::size_t f = 0; f < cameras.size(); ++f) {
        const catgs::FrameStats s = renderer->render_rgb8(cameras[f], render_options, image);
        const double values[kStages] = {s.preprocess_ms, s.scan_ms,      s.keys_ms,  s.sort_ms, s.ranges_ms,
                                        s.split_ms,      s.rasterize_ms, s.merge_ms, s.copy_ms, s.total_ms};
        for (int k = 0; k < kStages; ++k) stages[k].values.push_back(values[k]);
        pairs.values.push_back(static_cast<double>(s.pairs));
        visible.values.push_back(static_cast<double>(s.visible));
        arena.values.push_back(static_cast<double>(s.arena_bytes));
        window.values.push_back(s.window);
        splits.values.push_back(static_cast<double>(s.split_tasks));
        (s.key_frame ? key_total : cached_total).values.push_back(s.total_ms);
        nlohmann::json frame{{"frame", f},           {"key_frame", s.key_frame}, {"window", s.window},
                             {"pairs", s.pairs},     {"visible", s.visible},     {"arena_bytes", s.arena_bytes},
                             {"bands", s.bands},     {"tasks", s.tasks},         {"split_tasks", s.split_tasks},
                             {"split_k", s.split_k}};
        for (int k = 0; k < kStages; ++k) frame[std::string(stage_names[k]) + "_ms"] = values[k];
        frames.push_back(frame);
        if (!o.quiet && (f + 1) % std::max<std::size_t>(1, cameras.size() / 10) == 0)
            std::fprintf(stderr, "benchmark: %zu/%zu frames\n", f + 1, cameras.size());
    }

    std::printf("\n%-12s %10s %10s %10s\n", "stage (ms)", "median", "p90", "max");
    nlohmann::json summary;
    auto row = [&](const char* name, const Series& series, double scale, const char* format) {
        std::printf(format, name, series.percentile(0.5) * scale, series.percentile(0.9) * scale, series.max() * scale);
        summary[name] = {{"median", series.percentile(0.5) * scale},
                         {"p90", series.percentile(0.9) * scale},
                         {"max", series.max() * scale},
                         {"count", series.values.size()}};
    };
    for (int k = 0; k < kStages; ++k) row(stage_names[k], stages[k], 1.0, "%-12s %10.3f %10.3f %10.3f\n");
    row("key total", key_total, 1.0, "%-12s %10.3f %10.3f %10.3f\n");
    row("cached total", cached_total, 1.0, "%-12s %10.3f %10.3f %10.3f\n");
    row("pairs", pairs, 1.0, "%-12s %10.0f %10.0f %10.0f\n");
    row("visible", visible, 1.0, "%-12s %10.0f %10.0f %10.0f\n");
    row("window", window, 1.0, "%-12s %10.0f %10.0f %10.0f\n");
    row("split tasks", splits, 1.0, "%-12s %10.0f %10.0f %10.0f\n");
    row("arena MiB", arena, 1.0 / 1048576.0, "%-12s %10.1f %10.1f %10.1f\n");
    std::printf("key frames %zu, cached frames %zu\n", key_total.values.size(), cached_total.values.size());

    if (!o.json_out.empty()) {
        nlohmann::json doc{{"scene", nlohmann::json::parse(catgs::describe_json(*scene))},
                           {"scene_spec", o.scene},
                           {"grid", o.grid},
                           {"trajectory", o.trajectory},
                           {"renderer", renderer->name()},
                           {"pipeline", catgs::cli::describe_pipeline(render_options)},
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
    catgs::cli::add_pipeline_flags(app, o.pipeline);
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
