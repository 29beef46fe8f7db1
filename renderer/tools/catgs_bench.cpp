// catgs-bench: renders a camera path and reports per-stage times (CUDA events on the GPU),
// tile-Gaussian pairs, visible Gaussians and arena memory per frame, with median, p90 and max;
// key frames and cached frames apart. With --sweep it runs several pipeline configurations on
// the same scene and path and sets their times against their error to an exact reference
// render (PSNR, max 8-bit error, fraction of values more than one level off), for the
// time-against-error table and plot (renderer/tools/plot_sweep.sh).
// It links no OpenImageIO, so it runs on bare GPU hosts (see deploy/bundle.sh).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
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

namespace {

/// PSNR of identical images is infinite; tables and plots cap it here.
constexpr double kPsnrCap = 100.0;

struct Options {
    catgs::cli::SceneFlags scene{"builtin:city?gaussians=1000000&seed=1"};
    std::string grid = "1x1";
    int sh_degree = -1;  // -1: the scene's
    std::string up = "z";
    std::string trajectory = "builtin:survey?altitude=80&pitch=-45&speed=8&fps=30&frames=300";
    std::string backend = "cuda";
    std::string precision = "float";
    catgs::cli::PipelineFlags pipeline;
    std::string sweep;
    std::string reference = "none";
    std::string reference_backend;
    int error_every = 10;
    std::string json_out, csv_out;
    int width = 1920, height = 1080;
    double fov = 70.0;
    int warmup = 5;
    long max_frames = -1;
    int threads = 0;
    catgs::cli::ShardFlags sharding;
    bool quiet = false;
    bool image_digests = false;
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
    double min() const { return values.empty() ? 0 : *std::min_element(values.begin(), values.end()); }
    double mean() const {
        double s = 0;
        for (double v : values) s += v;
        return values.empty() ? 0 : s / static_cast<double>(values.size());
    }
};

using Config = catgs::cli::SweepEntry;

// The stages a renderer times: all but the server's encode, which is last.
constexpr std::size_t kRenderStages = catgs::kStageCount - 1;
static_assert(catgs::kStages[kRenderStages] == catgs::Stage::encode);

std::string stage_key(catgs::Stage stage) {
    return std::string(catgs::stage_name(stage)) + "_ms";
}

struct Result {
    std::string name, pipeline;
    std::array<Series, kRenderStages> stages;
    Series total, pairs, visible, chunks_culled, arena, key_total, cached_total, window, splits, psnr, max_abs,
        over_one, occluded_pairs;
    Series host;  // the render call's wall time: the stages plus what the caller waits beyond them
    std::uint64_t chunks = 0, occlusion_redrawn = 0;
    nlohmann::json frames = nlohmann::json::array();
};

// FNV-1a's step over the 8-bit image's 64-bit words, in four interleaved lanes folded at the
// end: enough to tell two renders apart when a change must leave every pixel as it was
// (renderer/tools/gpu_regression.sh compares them). Byte by byte, one dependent multiply a
// byte, it took about 30 ms a 4K frame (this development machine) and made a digesting
// benchmark run about four times longer on the GPU machine; the lanes take a fifth. Every step
// is a bijection of its lane, so one changed word always changes the digest. Digests before
// 2026-12-06 were bytewise FNV-1a: compare only bundles built on the same side of that change.
std::string image_digest(const catgs::ImageRGB8& image) {
    constexpr std::uint64_t kOffset = 14695981039346656037ull, kPrime = 1099511628211ull;
    constexpr int kLanes = 4, kShift = 29;  // the shift folds high bits down, which the multiply never does
    std::uint64_t lanes[kLanes];
    for (int k = 0; k < kLanes; ++k) lanes[k] = kOffset + k;  // a start a lane: FNV's offset, +1, +2, ...
    const std::uint8_t* bytes = image.rgb.data();
    const std::size_t size = image.rgb.size();
    std::size_t at = 0;
    for (; at + kLanes * sizeof(std::uint64_t) <= size; at += kLanes * sizeof(std::uint64_t))
        for (int k = 0; k < kLanes; ++k) {
            std::uint64_t word;
            std::memcpy(&word, bytes + at + k * sizeof word, sizeof word);
            lanes[k] = (lanes[k] ^ word) * kPrime;
            lanes[k] ^= lanes[k] >> kShift;
        }
    std::uint64_t h = (kOffset ^ size) * kPrime;
    for (; at < size; ++at) h = (h ^ bytes[at]) * kPrime;
    for (const std::uint64_t lane : lanes) {
        h = (h ^ lane) * kPrime;
        h ^= h >> kShift;
    }
    char text[17];
    std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(h));
    return text;
}

/// A sharded renderer (--shards) timed like any renderer: each frame's stats are the shards'
/// combined (combine_shard_stats), and the last frame's per-shard detail is kept for the JSON.
class ShardedFrames final : public catgs::Renderer {
public:
    explicit ShardedFrames(std::unique_ptr<catgs::ShardedRenderer> sharded) : sharded_(std::move(sharded)) {}
    void set_scene(std::shared_ptr<const catgs::Scene>) override {
        throw catgs::Error("a sharded renderer takes its scene when it plans its shards");
    }
    catgs::FrameStats render(const catgs::Camera& camera, const catgs::RenderOptions& options, catgs::ImageF& out,
                             const catgs::FrameHints* hints) override {
        last_ = sharded_->render(camera, options, out, hints);
        return catgs::combine_shard_stats(last_, sharded_->concurrent());
    }
    catgs::FrameStats render_rgb8(const catgs::Camera& camera, const catgs::RenderOptions& options,
                                  catgs::ImageRGB8& out, const catgs::FrameHints* hints) override {
        last_ = sharded_->render_rgb8(camera, options, out, hints);
        return catgs::combine_shard_stats(last_, sharded_->concurrent());
    }
    void reset_cache() override { sharded_->reset_cache(); }
    std::string name() const override { return sharded_->name(); }
    const catgs::ShardedRenderer& sharded() const { return *sharded_; }
    /// The last frame's composite and per-shard times, for its JSON entry.
    nlohmann::json last_frame_json() const {
        nlohmann::json shards = nlohmann::json::array();
        for (const catgs::FrameStats& part : last_.shards)
            shards.push_back({{"total_ms", part.total_ms}, {"pairs", part.pairs}, {"visible", part.visible}});
        return {{"shard_wall_ms", last_.total_ms},
                {"shard_render_ms", last_.render_ms},
                {"shard_transfer_ms", last_.transfer_ms},
                {"shard_merge_ms", last_.merge_ms},
                {"shard_copy_out_ms", last_.copy_out_ms},
                {"shard_peer_direct", last_.peer_direct},
                {"shard_peer_staged", last_.peer_staged},
                {"shard_order", last_.order},
                {"shards", shards}};
    }

private:
    std::unique_ptr<catgs::ShardedRenderer> sharded_;
    catgs::ShardedFrameStats last_;
};

Result run_config(catgs::Renderer& renderer, const std::vector<catgs::Camera>& cameras, const Config& config,
                  const Options& o, const std::vector<catgs::ImageRGB8>& references) {
    Result r;
    r.name = config.name;
    r.pipeline = catgs::cli::describe_pipeline(config.options);
    catgs::ImageRGB8 image;
    // Warm-up renders of the first camera, then a fresh cache so the timed path starts cold.
    for (int i = 0; i < o.warmup; ++i) renderer.render_rgb8(cameras[0], config.options, image);
    renderer.reset_cache();
    for (std::size_t f = 0; f < cameras.size(); ++f) {
        const auto called = std::chrono::steady_clock::now();
        const catgs::FrameStats s = renderer.render_rgb8(cameras[f], config.options, image);
        const double host_ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - called).count();
        r.host.values.push_back(host_ms);
        for (std::size_t k = 0; k < kRenderStages; ++k) r.stages[k].values.push_back(s.stage_ms.ms[k]);
        r.total.values.push_back(s.total_ms);
        r.pairs.values.push_back(static_cast<double>(s.pairs));
        r.visible.values.push_back(static_cast<double>(s.visible));
        r.chunks_culled.values.push_back(static_cast<double>(s.chunks_culled));
        r.chunks = s.chunks;
        r.arena.values.push_back(static_cast<double>(s.arena_bytes));
        r.window.values.push_back(s.window);
        r.splits.values.push_back(static_cast<double>(s.split_tasks));
        r.occluded_pairs.values.push_back(static_cast<double>(s.occluded_pairs));
        r.occlusion_redrawn += s.occlusion_redrawn;
        (s.key_frame ? r.key_total : r.cached_total).values.push_back(s.total_ms);
        nlohmann::json frame{{"frame", f},
                             {"key_frame", s.key_frame},
                             {"order_reused", s.order_reused},
                             {"window", s.window},
                             {"pairs", s.pairs},
                             {"visible", s.visible},
                             {"arena_bytes", s.arena_bytes},
                             {"bands", s.bands},
                             {"tasks", s.tasks},
                             {"split_tasks", s.split_tasks},
                             {"longest_list", s.longest_list},
                             {"split_k", s.split_k},
                             {"chunks", s.chunks},
                             {"chunks_culled", s.chunks_culled},
                             {"occluded", s.occluded},
                             {"occluded_pairs", s.occluded_pairs},
                             {"occlusion_redrawn", s.occlusion_redrawn}};
        for (std::size_t k = 0; k < kRenderStages; ++k) frame[stage_key(catgs::kStages[k])] = s.stage_ms.ms[k];
        frame["total_ms"] = s.total_ms;
        frame["host_ms"] = host_ms;
        // The bench kit (shared/bench-kit/summarize.py) reads the copy-out time by its old name.
        frame["copy_ms"] = s.stage_ms[catgs::Stage::copy_out];
        if (!references.empty() && f % static_cast<std::size_t>(o.error_every) == 0) {
            const catgs::ImageError e = catgs::compare(image, references[f / static_cast<std::size_t>(o.error_every)]);
            const double psnr = std::min(e.psnr, kPsnrCap);
            r.psnr.values.push_back(psnr);
            r.max_abs.values.push_back(e.max_abs);
            r.over_one.values.push_back(e.fraction_over_one);
            frame["psnr"] = psnr;
            frame["max_abs"] = e.max_abs;
            frame["fraction_over_one_level"] = e.fraction_over_one;
        }
        if (o.image_digests) frame["image_digest"] = image_digest(image);
        if (const auto* sharded = dynamic_cast<const ShardedFrames*>(&renderer))
            frame.update(sharded->last_frame_json());
        r.frames.push_back(frame);
        if (!o.quiet && (f + 1) % std::max<std::size_t>(1, cameras.size() / 5) == 0)
            std::fprintf(stderr, "%s: %zu/%zu frames\n", config.name.c_str(), f + 1, cameras.size());
    }
    return r;
}

nlohmann::json stats_json(const Series& s) {
    return {{"median", s.percentile(0.5)}, {"p90", s.percentile(0.9)}, {"max", s.max()}, {"count", s.values.size()}};
}

void print_detail(const Result& r) {
    std::printf("\n== %s (%s)\n%-13s %10s %10s %10s\n", r.name.c_str(), r.pipeline.c_str(), "stage (ms)", "median",
                "p90", "max");
    auto row = [](const char* name, const Series& s, double scale, const char* format) {
        std::printf(format, name, s.percentile(0.5) * scale, s.percentile(0.9) * scale, s.max() * scale);
    };
    for (std::size_t k = 0; k < kRenderStages; ++k)
        row(std::string(catgs::stage_name(catgs::kStages[k])).c_str(), r.stages[k], 1.0,
            "%-13s %10.3f %10.3f %10.3f\n");
    row("total", r.total, 1.0, "%-13s %10.3f %10.3f %10.3f\n");
    row("key total", r.key_total, 1.0, "%-13s %10.3f %10.3f %10.3f\n");
    row("cached total", r.cached_total, 1.0, "%-13s %10.3f %10.3f %10.3f\n");
    row("host wall", r.host, 1.0, "%-13s %10.3f %10.3f %10.3f\n");
    row("pairs", r.pairs, 1.0, "%-13s %10.0f %10.0f %10.0f\n");
    row("visible", r.visible, 1.0, "%-13s %10.0f %10.0f %10.0f\n");
    if (r.chunks > 0) row("chunks culled", r.chunks_culled, 1.0, "%-13s %10.0f %10.0f %10.0f\n");
    row("window", r.window, 1.0, "%-13s %10.0f %10.0f %10.0f\n");
    row("split tasks", r.splits, 1.0, "%-13s %10.0f %10.0f %10.0f\n");
    row("occluded prs", r.occluded_pairs, 1.0, "%-13s %10.0f %10.0f %10.0f\n");
    row("arena MiB", r.arena, 1.0 / 1048576.0, "%-13s %10.1f %10.1f %10.1f\n");
    std::printf("key frames %zu, cached frames %zu, redrawn past the occlusion cut %llu", r.key_total.values.size(),
                r.cached_total.values.size(), static_cast<unsigned long long>(r.occlusion_redrawn));
    if (!r.psnr.values.empty())
        std::printf("; error on %zu frames: PSNR mean %.2f worst %.2f dB, max %0.f levels, >1 level %.5f%%",
                    r.psnr.values.size(), r.psnr.mean(), r.psnr.min(), r.max_abs.max(), 100.0 * r.over_one.max());
    std::printf("\n");
}

std::vector<Config> make_configs(const Options& o) {
    if (!o.sweep.empty()) return catgs::cli::parse_sweep(o.sweep);
    Config c;
    c.name = "single";
    catgs::cli::apply_pipeline_flags(o.pipeline, c.options);
    return {c};
}

// The reference: a per-frame render in double, no cache, no split, with exact culling (every
// Gaussian at every pixel) or opacity-aware culling (which the tests show loses nothing
// relative to exact, and is affordable for large scenes), every error_every frames.
std::vector<catgs::ImageRGB8> render_references(const Options& o, const std::shared_ptr<catgs::Scene>& scene,
                                                const std::vector<catgs::Camera>& cameras) {
    std::vector<catgs::ImageRGB8> references;
    if (o.reference == "none") return references;
    auto ref = catgs::make_renderer(o.reference_backend.empty() ? o.backend : o.reference_backend,
                                    catgs::Precision::double_, o.threads);
    ref->set_scene(scene);
    catgs::RenderOptions ro;
    ro.culling = catgs::parse_culling(o.reference);
    for (std::size_t f = 0; f < cameras.size(); f += static_cast<std::size_t>(o.error_every)) {
        references.emplace_back();
        ref->render_rgb8(cameras[f], ro, references.back());
        if (!o.quiet)
            std::fprintf(stderr, "reference (%s, %s): frame %zu\n", ref->name().c_str(), o.reference.c_str(), f);
    }
    return references;
}

nlohmann::json result_json(const Result& r) {
    nlohmann::json stages;
    for (std::size_t k = 0; k < kRenderStages; ++k)
        stages[std::string(catgs::stage_name(catgs::kStages[k]))] = stats_json(r.stages[k]);
    stages["total"] = stats_json(r.total);
    return {{"name", r.name},
            {"pipeline", r.pipeline},
            {"stages_ms", stages},
            {"key_total_ms", stats_json(r.key_total)},
            {"cached_total_ms", stats_json(r.cached_total)},
            {"host_ms", stats_json(r.host)},
            {"pairs", stats_json(r.pairs)},
            {"visible", stats_json(r.visible)},
            {"chunks", r.chunks},
            {"chunks_culled", stats_json(r.chunks_culled)},
            {"window", stats_json(r.window)},
            {"split_tasks", stats_json(r.splits)},
            {"occluded_pairs", stats_json(r.occluded_pairs)},
            {"occlusion_redrawn", r.occlusion_redrawn},
            {"peak_arena_bytes", r.arena.max()},
            {"psnr_mean", r.psnr.mean()},
            {"psnr_worst", r.psnr.min()},
            {"max_abs", r.max_abs.max()},
            {"fraction_over_one_level", r.over_one.max()},
            {"frames", r.frames}};
}

// One row per configuration on stdout and in --csv-out.
void print_summary(const Options& o, const std::vector<Result>& results) {
    std::printf("\n%-22s %9s %9s %9s %9s %9s %10s %8s %8s %6s %5s\n", "configuration", "median", "p90", "max",
                "key med", "cach med", "pairs med", "PSNR", "worst", "max", "W med");
    std::ofstream csv;
    if (!o.csv_out.empty()) {
        csv.open(o.csv_out);
        if (!csv) throw catgs::Error("--csv-out '" + o.csv_out + "': cannot open for writing");
        csv << "name,pipeline,median_ms,p90_ms,max_ms,key_median_ms,cached_median_ms,key_frames,cached_frames,"
               "pairs_median,psnr_mean,psnr_worst,max_abs,fraction_over_one_level,window_median\n";
    }
    for (const Result& r : results) {
        const Series& total = r.total;
        std::printf("%-22s %9.3f %9.3f %9.3f %9.3f %9.3f %10.0f %8.2f %8.2f %6.0f %5.0f\n", r.name.c_str(),
                    total.percentile(0.5), total.percentile(0.9), total.max(), r.key_total.percentile(0.5),
                    r.cached_total.percentile(0.5), r.pairs.percentile(0.5), r.psnr.mean(), r.psnr.min(),
                    r.max_abs.max(), r.window.percentile(0.5));
        if (csv)
            csv << r.name << ",\"" << r.pipeline << "\"," << total.percentile(0.5) << "," << total.percentile(0.9)
                << "," << total.max() << "," << r.key_total.percentile(0.5) << "," << r.cached_total.percentile(0.5)
                << "," << r.key_total.values.size() << "," << r.cached_total.values.size() << ","
                << r.pairs.percentile(0.5) << "," << r.psnr.mean() << "," << r.psnr.min() << "," << r.max_abs.max()
                << "," << r.over_one.max() << "," << r.window.percentile(0.5) << "\n";
    }
}

// The CUDA hardware queues the run had (gpu_queues.hpp), for the record: empty means the
// driver's default of 8.
std::string env_or_empty(const char* name) {
    const char* value = std::getenv(name);
    return value ? value : "";
}

int run(const Options& o) {
    const catgs::Precision precision = catgs::parse_precision(o.precision);
    const auto [grid_x, grid_y] = catgs::parse_grid(o.grid);
    const int up_axis = catgs::parse_up_axis(o.up);
    if (o.warmup < 0) throw catgs::Error("--warmup must be >= 0");
    if (o.error_every < 1) throw catgs::Error("--error-every must be >= 1");
    if (o.reference != "none" && o.reference != "exact" && o.reference != "opacity-aware")
        throw catgs::Error("--reference '" + o.reference + "': expected none, exact or opacity-aware");
    const std::vector<Config> configs = make_configs(o);

    auto scene = std::make_shared<catgs::Scene>(catgs::cli::load_scene(o.scene, o.quiet));
    if (grid_x * grid_y > 1) *scene = catgs::replicate_grid(*scene, grid_x, grid_y, up_axis);
    if (o.sh_degree >= 0) catgs::truncate_sh(*scene, o.sh_degree);
    const catgs::Intrinsics intrinsics = catgs::intrinsics_from_fov(o.width, o.height, o.fov);
    catgs::validate(intrinsics, "--width/--height/--fov");
    std::vector<catgs::Camera> cameras = catgs::load_trajectory(o.trajectory, scene->bounds, intrinsics);
    if (o.max_frames >= 0 && cameras.size() > static_cast<std::size_t>(o.max_frames))
        cameras.resize(static_cast<std::size_t>(o.max_frames));
    if (cameras.empty()) throw catgs::Error("the camera path has no cameras");

    std::unique_ptr<catgs::Renderer> renderer;
    std::string renderer_name;
    if (auto sharded = catgs::cli::make_sharded_renderer(o.sharding, *scene, o.backend, precision, o.threads)) {
        renderer_name = catgs::cli::describe_sharding(o.sharding, *sharded, o.backend);
        renderer = std::make_unique<ShardedFrames>(std::move(sharded));
    } else {
        renderer = catgs::make_renderer(o.backend, precision, o.threads);
        renderer->set_scene(scene);
        renderer_name = renderer->name();
    }
    std::printf("scene: %s\nrenderer: %s, %dx%d, %zu frames, %d warm-up renders, %zu configuration(s)\n",
                catgs::describe(*scene).c_str(), renderer_name.c_str(), cameras[0].intrinsics.width,
                cameras[0].intrinsics.height, cameras.size(), o.warmup, configs.size());
    const std::vector<catgs::ImageRGB8> references = render_references(o, scene, cameras);
    std::fflush(stdout);

    std::vector<Result> results;
    for (const Config& c : configs) {
        results.push_back(run_config(*renderer, cameras, c, o, references));
        print_detail(results.back());
        std::fflush(stdout);
    }
    print_summary(o, results);
    if (!o.json_out.empty()) {
        nlohmann::json doc_results = nlohmann::json::array();
        for (const Result& r : results) doc_results.push_back(result_json(r));
        nlohmann::json doc{{"scene", nlohmann::json::parse(catgs::describe_json(*scene))},
                           {"scene_spec", o.scene.scene},
                           {"drop_invalid", o.scene.drop_invalid},
                           {"grid", o.grid},
                           {"trajectory", o.trajectory},
                           {"renderer", renderer_name},
                           {"cuda_device_max_connections", env_or_empty(catgs::kGpuHardwareQueuesVariable)},
                           {"shards", o.sharding.shards},
                           {"width", cameras[0].intrinsics.width},
                           {"height", cameras[0].intrinsics.height},
                           {"warmup", o.warmup},
                           {"reference", o.reference},
                           {"error_every", o.error_every},
                           {"results", doc_results}};
        std::ofstream out(o.json_out);
        if (!out) throw catgs::Error("--json-out '" + o.json_out + "': cannot open for writing");
        out << doc.dump(1) << "\n";
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    catgs::request_gpu_hardware_queues();
    Options o;
    CLI::App app{"catgs-bench: per-stage timings of a renderer along a camera path, and time against error"};
    catgs::cli::add_scene_flags(app, o.scene);
    app.add_option("--sh-degree", o.sh_degree,
                   "render with the SH coefficients above this degree (0..3) dropped; 0: view-independent colour "
                   "(default: the scene's degree)")
        ->check(CLI::Range(0, 3));
    app.add_option("--grid", o.grid, "replicate the scene NxM over the horizontal axes (e.g. 3x3)")
        ->capture_default_str();
    app.add_option("--up", o.up, "the scene's up axis (x, y, z, -y, ...) for --grid")->capture_default_str();
    app.add_option("--trajectory", o.trajectory, "trajectory file or builtin:survey|orbit|flythrough|hover?...")
        ->capture_default_str();
    app.add_option("--backend", o.backend, "cpu or cuda (" + catgs::available_backends() + " built in)")
        ->capture_default_str();
    app.add_option("--precision", o.precision, "float or double")->capture_default_str();
    catgs::cli::add_pipeline_flags(app, o.pipeline);
    app.add_option(
        "--sweep", o.sweep,
        "configurations to compare, 'name: flags; name: flags' or @file with one 'name: flags' a line "
        "(flags as --split, --cache, --window, ..., applied over the defaults, so 'plain: --cache off --split off' is "
        "the per-frame pipeline); replaces the single configuration");
    app.add_option("--reference", o.reference,
                   "error reference, rendered in double without cache or split: none, exact, or opacity-aware")
        ->capture_default_str();
    app.add_option("--reference-backend", o.reference_backend, "backend for the reference (default: --backend)");
    app.add_option("--error-every", o.error_every, "compare every Nth frame with the reference")->capture_default_str();
    app.add_option("--width", o.width, "image width")->capture_default_str()->check(catgs::image_side());
    app.add_option("--height", o.height, "image height")->capture_default_str()->check(catgs::image_side());
    app.add_option("--fov", o.fov, "horizontal field of view in degrees")
        ->capture_default_str()
        ->check(catgs::horizontal_fov());
    app.add_option("--warmup", o.warmup, "untimed renders of the first camera before timing")->capture_default_str();
    app.add_option("--max-frames", o.max_frames, "time at most this many cameras (-1: all)")->capture_default_str();
    app.add_option("--threads", o.threads, "CPU threads for the cpu backend (0: all)")
        ->check(catgs::thread_count())
        ->capture_default_str();
    catgs::cli::add_shard_flags(app, o.sharding);
    app.add_option("--json-out", o.json_out, "write per-frame and summary results as JSON to this file");
    app.add_option("--csv-out", o.csv_out, "write one CSV row per configuration to this file");
    app.add_flag("--quiet", o.quiet, "no progress output on stderr");
    app.add_flag("--image-digests", o.image_digests,
                 "add each frame's image digest (64 bits, FNV-1a steps over the 8-bit RGB's words) to --json-out, to "
                 "check that a change leaves every image bit-identical");
    return catgs::run_command_line(app, argc, argv, "catgs-bench", [&] { return run(o); });
}
