// catgs-encode-bench: the server's frame encoders one by one, timed on frames rendered by the
// CPU reference renderer from the built-in city (a realistic image: neither noise nor flat),
// at each size asked for. Prints ms per frame (wall median, p90; CPU of all threads, mean) and
// bytes per frame; --json writes
// the same as JSON. Links no OpenImageIO, gRPC or CUDA renderer: deploy/bundle.sh packs it for
// the GPU host. Usage: catgs-encode-bench [--sizes 1920x1080,...] [--threads 1,2,16] [--json]
#include <zlib.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "catgs/camera.hpp"
#include "catgs/common/command_line.hpp"
#include "catgs/common/exit_codes.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/error.hpp"
#include "catgs/parallel.hpp"
#include "catgs/scene_io.hpp"
#include "catgs/server/encode_methods.hpp"
#include "catgs/trajectory.hpp"

namespace {

using catgs::ImageRGB8;
namespace srv = catgs::server;

struct Options {
    std::string scene = "builtin:city?gaussians=300000&seed=1";
    std::string trajectory = "builtin:survey?altitude=80&pitch=-45&speed=8&fps=30&frames=60";
    double fov = 60;
    std::string sizes = "1280x720,1920x1080,3840x2160";
    std::string threads;  // default: 1 and every core
    std::string only;     // encoder names to run, comma-separated; empty: all
    int frames = 20;
    int warmup = 2;
    int quality = 85;
    bool chroma_444 = false;
    bool json = false;
};

std::vector<std::string> split_list(const std::string& text) {
    std::vector<std::string> items;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) items.push_back(item);
    return items;
}

std::pair<int, int> parse_size(const std::string& text) {
    int w = 0, h = 0;
    char x = 0, extra = 0;
    if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || x != 'x' || w < 1 || h < 1 || w > 16384 ||
        h > 16384)
        throw catgs::Error("--sizes '" + text + "': expected WIDTHxHEIGHT, each 1..16384");
    return {w, h};
}

std::vector<int> parse_threads(const std::string& text) {
    std::vector<int> threads;
    for (const std::string& item : split_list(text)) {
        char* end = nullptr;
        const long n = std::strtol(item.c_str(), &end, 10);
        if (*end != '\0' || n < 1 || n > 1024) throw catgs::Error("--threads '" + item + "': expected 1..1024");
        threads.push_back(static_cast<int>(n));
    }
    if (threads.empty()) throw catgs::Error("--threads '" + text + "': no thread count");
    return threads;
}

// A variant: its name, how many threads one frame may use, and the call.
struct Variant {
    std::string name;
    int threads = 1;
    std::function<void(const ImageRGB8&, std::string&)> encode;
};

std::vector<Variant> make_variants(const Options& o, const std::vector<int>& thread_counts,
                                   std::map<int, std::unique_ptr<srv::EncodePool>>& pools) {
    using F = srv::PngFilter;
    const int q = o.quality;
    const bool c444 = o.chroma_444;
    std::vector<Variant> v;
    v.push_back(
        {"jpeg-turbo", 1, [=](const ImageRGB8& im, std::string& out) { srv::encode_jpeg_turbo(im, q, c444, out); }});
    for (int t : thread_counts) {
        if (t < 2) continue;
        auto& pool = pools[t];
        if (!pool) pool = std::make_unique<srv::EncodePool>(t);
        srv::EncodePool* p = pool.get();
        v.push_back({"jpeg-turbo-strips", t,
                     [=](const ImageRGB8& im, std::string& out) { srv::encode_jpeg_strips(im, q, c444, t, *p, out); }});
    }
    if (srv::nvjpeg_unusable_reason().empty())
        v.push_back({"jpeg-nvjpeg", 1,
                     [=](const ImageRGB8& im, std::string& out) { srv::encode_jpeg_nvjpeg(im, q, c444, out); }});
    v.push_back({"png-libpng-adaptive", 1, srv::encode_png_libpng_adaptive});
    v.push_back({"png-libpng-up", 1, [](const ImageRGB8& im, std::string& out) {
                     srv::encode_png_libpng(im, F::up, 1, Z_DEFAULT_STRATEGY, out);
                 }});
    v.push_back({"png-libpng-up-rle", 1,
                 [](const ImageRGB8& im, std::string& out) { srv::encode_png_libpng(im, F::up, 1, Z_RLE, out); }});
    v.push_back(
        {"png-spng-up", 1, [](const ImageRGB8& im, std::string& out) { srv::encode_png_spng(im, F::up, 1, out); }});
    v.push_back({"png-libdeflate-up", 1,
                 [](const ImageRGB8& im, std::string& out) { srv::encode_png_libdeflate(im, F::up, 1, out); }});
    v.push_back({"png-libdeflate-paeth", 1,
                 [](const ImageRGB8& im, std::string& out) { srv::encode_png_libdeflate(im, F::paeth, 1, out); }});
    for (int t : thread_counts) {
        auto& pool = pools[t];
        if (!pool) pool = std::make_unique<srv::EncodePool>(t);
        srv::EncodePool* p = pool.get();
        for (const auto& [suffix, filter, strategy] :
             {std::tuple{"up", F::up, Z_DEFAULT_STRATEGY}, std::tuple{"paeth", F::paeth, Z_DEFAULT_STRATEGY},
              std::tuple{"up-rle", F::up, Z_RLE}}) {
            v.push_back({std::string("png-parallel-") + suffix, t, [=](const ImageRGB8& im, std::string& out) {
                             srv::encode_png_parallel(im, filter, 1, strategy, t, *p, out);
                         }});
        }
    }
    if (!o.only.empty()) {
        const std::vector<std::string> only = split_list(o.only);
        std::erase_if(v, [&](const Variant& x) { return std::find(only.begin(), only.end(), x.name) == only.end(); });
    }
    return v;
}

ImageRGB8 render_frame(const catgs::Scene& scene, const Options& o, int width, int height) {
    const catgs::Intrinsics intrinsics = catgs::intrinsics_from_fov(width, height, o.fov);
    const std::vector<catgs::Camera> cameras = catgs::load_trajectory(o.trajectory, scene.bounds, intrinsics);
    if (cameras.empty()) throw catgs::Error("--trajectory '" + o.trajectory + "' has no cameras");
    catgs::CpuRenderer<float> renderer(0);
    catgs::ImageF image;
    // Mid-flight: the first pose of a survey can sit at the block's edge, half sky.
    renderer.render(scene, cameras[cameras.size() / 2], catgs::RenderOptions{}, image);
    return catgs::to_rgb8(image);
}

// CPU time of every thread of the process: what an encode costs, whatever else the machine
// runs (wall time on a shared machine measures the neighbours too).
double process_cpu_ms() {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

double percentile(std::vector<double> values, double p) {
    std::sort(values.begin(), values.end());
    const std::size_t i = static_cast<std::size_t>(p * static_cast<double>(values.size() - 1) + 0.5);
    return values[std::min(i, values.size() - 1)];
}

int run(const Options& o) {
    if (o.frames < 1) throw catgs::Error("--frames " + std::to_string(o.frames) + ": must be >= 1");
    if (o.warmup < 0) throw catgs::Error("--warmup " + std::to_string(o.warmup) + ": must be >= 0");
    if (o.quality < 1 || o.quality > 100) throw catgs::Error("--quality " + std::to_string(o.quality) + ": 1..100");
    std::vector<std::pair<int, int>> sizes;
    for (const std::string& s : split_list(o.sizes)) sizes.push_back(parse_size(s));
    if (sizes.empty()) throw catgs::Error("--sizes '" + o.sizes + "': no size");
    std::vector<int> thread_counts =
        parse_threads(o.threads.empty() ? "1," + std::to_string(catgs::default_thread_count()) : o.threads);
    std::sort(thread_counts.begin(), thread_counts.end());
    thread_counts.erase(std::unique(thread_counts.begin(), thread_counts.end()), thread_counts.end());

    std::map<int, std::unique_ptr<srv::EncodePool>> pools;
    const std::vector<Variant> variants = make_variants(o, thread_counts, pools);
    if (variants.empty()) throw catgs::Error("--only '" + o.only + "': matches no encoder");
    const catgs::Scene scene = catgs::load_scene(o.scene);
    nlohmann::json results = nlohmann::json::array();
    if (!o.json)
        std::printf("%-22s %7s %10s %9s %9s %9s %10s %7s\n", "encoder", "threads", "size", "ms_p50", "ms_p90", "cpu_ms",
                    "bytes", "ratio");
    for (const auto& [w, h] : sizes) {
        const ImageRGB8 image = render_frame(scene, o, w, h);
        for (const Variant& variant : variants) {
            std::string out;
            for (int i = 0; i < o.warmup; ++i) variant.encode(image, out);
            std::vector<double> ms;
            const double cpu_start = process_cpu_ms();
            for (int i = 0; i < o.frames; ++i) {
                const auto start = std::chrono::steady_clock::now();
                variant.encode(image, out);
                ms.push_back(
                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
            }
            const double cpu_ms = (process_cpu_ms() - cpu_start) / o.frames;
            const double p50 = percentile(ms, 0.5), p90 = percentile(ms, 0.9);
            const double ratio = static_cast<double>(out.size()) / static_cast<double>(image.rgb.size());
            const std::string size = std::to_string(w) + "x" + std::to_string(h);
            if (o.json) {
                results.push_back({{"encoder", variant.name},
                                   {"threads", variant.threads},
                                   {"width", w},
                                   {"height", h},
                                   {"ms_p50", p50},
                                   {"ms_p90", p90},
                                   {"cpu_ms", cpu_ms},
                                   {"bytes", out.size()},
                                   {"ratio", ratio}});
            } else {
                std::printf("%-22s %7d %10s %9.2f %9.2f %9.2f %10zu %7.3f\n", variant.name.c_str(), variant.threads,
                            size.c_str(), p50, p90, cpu_ms, out.size(), ratio);
                std::fflush(stdout);
            }
        }
    }
    if (o.json) {
        const nlohmann::json doc = {{"scene", o.scene},
                                    {"frames", o.frames},
                                    {"quality", o.quality},
                                    {"chroma", o.chroma_444 ? "444" : "420"},
                                    {"cores", catgs::default_thread_count()},
                                    {"results", results}};
        std::cout << doc.dump(2) << "\n";
    }
    return catgs::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"catgs-encode-bench: the frame encoders timed on rendered frames"};
    Options o;
    app.add_option("--sizes", o.sizes, "comma-separated WIDTHxHEIGHT")->capture_default_str();
    app.add_option("--threads", o.threads,
                   "comma-separated threads per frame for the parallel encoders (default: 1 and every core)");
    app.add_option("--only", o.only, "comma-separated encoder names (default: all)");
    app.add_option("--frames", o.frames, "timed encodes per encoder and size")->capture_default_str();
    app.add_option("--warmup", o.warmup, "untimed encodes first")->capture_default_str();
    app.add_option("--quality", o.quality, "JPEG quality 1..100")->check(catgs::jpeg_quality())->capture_default_str();
    app.add_flag("--444", o.chroma_444, "JPEG 4:4:4 chroma instead of 4:2:0");
    app.add_option("--scene", o.scene, "the scene rendered (PLY, .splat or builtin:city?...)")->capture_default_str();
    app.add_option("--trajectory", o.trajectory, "the flight whose middle pose is rendered")->capture_default_str();
    app.add_option("--fov", o.fov, "horizontal field of view, degrees")
        ->check(catgs::horizontal_fov())
        ->capture_default_str();
    app.add_flag("--json", o.json, "print JSON instead of the table");
    return catgs::run_command_line(app, argc, argv, "catgs-encode-bench", [&] { return run(o); });
}
