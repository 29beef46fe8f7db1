#include "cli_options.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>

#include "catgs/cache.hpp"
#include "catgs/error.hpp"
#include "catgs/progress.hpp"
#include "catgs/regular_file.hpp"

namespace catgs::cli {

PipelineFlags::PipelineFlags(const RenderOptions& o)
    : culling(culling_name(o.culling)),
      split(o.catgs.split_auto    ? "auto"
            : o.catgs.split_k > 0 ? std::to_string(o.catgs.split_k)
                                  : "off"),
      split_tail(o.catgs.split_tail_transmittance),
      cache(cache_mode_name(o.catgs.cache)),
      window(o.catgs.adaptive_window ? "adaptive" : std::to_string(o.catgs.window)),
      window_start(o.catgs.window),
      window_cost(window_cost_name(o.catgs.window_cost)),
      guard_px(o.catgs.guard_px),
      guard_m(o.catgs.guard_translation),
      resort(o.catgs.resort_cached ? "on" : "off"),
      chunks(o.chunk_culling ? "on" : "off"),
      reuse_order_max_deg(angle_name(o.catgs.reuse_order_max_angle)),
      occlusion_cut(o.catgs.occlusion_cut ? "on" : "off") {}

std::string PipelineFlags::angle_name(double radians) {
    if (!std::isfinite(radians)) return "any";
    std::ostringstream out;
    out << radians * 180.0 / kPi;
    return out.str();
}

namespace {

/// --help's default of --reuse-order-max-deg as a person reads it: "0.0000573 (1e-6 rad)"
/// rather than the flag's value text, 5.72958e-05, which stays what is parsed; `unit` goes
/// after the degrees ("0.0000573 deg (1e-6 rad)").
std::string readable_degrees(const std::string& flag_value, const std::string& unit = "") {
    const std::optional<double> degrees = parse_degrees(flag_value);
    if (!degrees || !(*degrees > 0)) return flag_value;
    // Three significant digits in positional notation, trailing zeros dropped.
    const int decimals = std::max(0, 2 - static_cast<int>(std::floor(std::log10(*degrees))));
    char text[64];
    std::snprintf(text, sizeof text, "%.*f", decimals, *degrees);
    std::string shown = text;
    if (shown.find('.') != std::string::npos) {
        while (shown.back() == '0') shown.pop_back();
        if (shown.back() == '.') shown.pop_back();
    }
    std::snprintf(text, sizeof text, "%.3g", *degrees * kPi / 180.0);
    std::string radians = text;
    for (const char* padded : {"e-0", "e+0"})
        if (const auto at = radians.find(padded); at != std::string::npos) radians.erase(at + 2, 1);
    return shown + unit + " (" + radians + " rad)";
}

}  // namespace

void add_pipeline_flags(CLI::App& app, PipelineFlags& f) {
    app.add_option("--culling", f.culling, "exact, bbox3sigma or opacity-aware")->capture_default_str();
    app.add_option(
           "--split", f.split,
           "tile task splitting: off, auto, or k (lists longer than k are split; with --window-cost time, only on "
           "paths where splitting measures faster, and k moves by powers of two within k/8..4k to the one that "
           "measures fastest)")
        ->capture_default_str();
    app.add_option("--split-tail", f.split_tail,
                   "early-termination transmittance of split sub-tasks after the first (1e-4: the unsplit "
                   "threshold; higher is the paper's faster, lossier setting)")
        ->capture_default_str();
    app.add_option("--cache", f.cache,
                   "inter-frame cache: off, speculative (CaT-GS), or unspeculated (shows the artifacts)")
        ->capture_default_str();
    app.add_option("--window", f.window, "speculation window W: adaptive, or a fixed 1..16")->capture_default_str();
    app.add_option("--window-start", f.window_start, "initial W of the adaptive window")->capture_default_str();
    app.add_option("--window-cost", f.window_cost,
                   "what the adaptive window chooses W from, within the motion bound: time (each frame's measured "
                   "time; plain frames where no window pays), work (each frame's work counts: reproducible), or off "
                   "(motion alone)")
        ->capture_default_str();
    app.add_option("--guard-px", f.guard_px, "cache guard band: footprint dilation and envelope radius, pixels")
        ->capture_default_str();
    app.add_option("--guard-m", f.guard_m, "cache envelope radius in metres")->capture_default_str();
    app.add_option("--resort", f.resort,
                   "with the cache: on re-sorts every cached frame by the current depth; off reuses the key frame's "
                   "depth order while the camera has turned at most --reuse-order-max-deg (faster)")
        ->capture_default_str();
    app.add_option("--reuse-order-max-deg", f.reuse_order_max_deg,
                   "with --resort off: a cached frame reuses the key frame's depth order while it has turned at "
                   "most this many degrees from the key frame (translation keeps the order), else it re-sorts; "
                   "'any': always reuse (the paper's cache)")
        ->default_str(readable_degrees(f.reuse_order_max_deg));
    app.add_option("--chunks", f.chunks,
                   "chunk-level culling: skip the scene's spatial chunks that no pose can see (on or off; exact "
                   "culling never skips)")
        ->capture_default_str();
    app.add_option("--occlusion-cut", f.occlusion_cut,
                   "plain frames leave out the Gaussians behind where the last frame's tiles turned opaque, check "
                   "every tile and draw the frame again in full where one did not (on or off; the image is the same; "
                   "float renders; off by default: a miss redraws the whole frame, which so far costs more than the "
                   "cut saves)")
        ->capture_default_str();
}

void apply_pipeline_flags(const PipelineFlags& f, RenderOptions& options) {
    options.culling = parse_culling(f.culling);
    CatgsOptions& c = options.catgs;
    if (f.split == "off") {
        c.split_k = 0;
    } else if (f.split == "auto") {
        c.split_auto = true;
    } else if (const auto k = parse_split_k(f.split)) {
        c.split_k = *k;
    } else {
        throw Error("--split '" + f.split + "': expected off, auto or an integer k in 1..16777216");
    }
    if (!(f.split_tail >= kMinTransmittance && f.split_tail < 1.0))
        throw Error("--split-tail " + std::to_string(f.split_tail) + ": expected a transmittance in [1e-4, 1)");
    c.split_tail_transmittance = f.split_tail;
    c.cache = parse_cache_mode(f.cache);
    if (f.window == "adaptive") {
        c.adaptive_window = true;
        c.window = f.window_start;
    } else {
        try {
            std::size_t used = 0;
            const int w = std::stoi(f.window, &used);
            if (used != f.window.size() || w < 1 || w > kMaxWindow) throw std::invalid_argument(f.window);
            c.adaptive_window = false;
            c.window = w;
        } catch (const std::logic_error&) {
            throw Error("--window '" + f.window + "': expected adaptive or an integer in 1..16");
        }
    }
    if (f.window_start < 1 || f.window_start > kMaxWindow)
        throw Error("--window-start " + std::to_string(f.window_start) + ": expected 1..16");
    if (f.window_cost != "off" && f.window_cost != "time" && f.window_cost != "work")
        throw Error("--window-cost '" + f.window_cost + "': expected time, work or off");
    c.window_cost = parse_window_cost(f.window_cost);
    if (!(f.guard_px >= 0 && f.guard_px <= 64)) throw Error("--guard-px: expected 0..64 pixels");
    if (!(f.guard_m >= 0 && f.guard_m <= 100)) throw Error("--guard-m: expected 0..100 metres");
    c.guard_px = f.guard_px;
    c.guard_translation = f.guard_m;
    if (f.resort != "on" && f.resort != "off") throw Error("--resort '" + f.resort + "': expected on or off");
    c.resort_cached = f.resort == "on";
    if (f.reuse_order_max_deg == "any") {
        c.reuse_order_max_angle = std::numeric_limits<double>::infinity();
    } else if (const auto degrees = parse_degrees(f.reuse_order_max_deg)) {
        c.reuse_order_max_angle = *degrees * kPi / 180.0;
    } else {
        throw Error("--reuse-order-max-deg '" + f.reuse_order_max_deg + "': expected 'any' or degrees in 0..180");
    }
    if (f.chunks != "on" && f.chunks != "off") throw Error("--chunks '" + f.chunks + "': expected on or off");
    options.chunk_culling = f.chunks == "on";
    if (f.occlusion_cut != "on" && f.occlusion_cut != "off")
        throw Error("--occlusion-cut '" + f.occlusion_cut + "': expected on or off");
    c.occlusion_cut = f.occlusion_cut == "on";
}

std::string describe_pipeline(const RenderOptions& o) {
    std::string s = culling_name(o.culling);
    const CatgsOptions& c = o.catgs;
    s += c.split_auto ? ", split auto" : (c.split_k ? ", split k=" + std::to_string(c.split_k) : ", no split");
    s += std::string(", cache ") + cache_mode_name(c.cache);
    if (c.cache != CacheMode::off && !c.adaptive_window) s += ", W=" + std::to_string(c.window);
    if (c.cache != CacheMode::off && c.adaptive_window) s += ", W adaptive";
    if (c.cache != CacheMode::off && c.adaptive_window && c.window_cost != WindowCost::off)
        s += std::string(" by ") + window_cost_name(c.window_cost);
    if (c.cache != CacheMode::off && !c.resort_cached)
        s += std::isfinite(c.reuse_order_max_angle)
                 ? ", depth order reused within " +
                       readable_degrees(PipelineFlags::angle_name(c.reuse_order_max_angle), " deg")
                 : ", depth order reused";
    if (!o.chunk_culling) s += ", no chunk culling";
    if (o.catgs.occlusion_cut) s += ", occlusion cut";
    return s;
}

void add_scene_flags(CLI::App& app, SceneFlags& flags) {
    app.add_option("--scene", flags.scene,
                   "scene file (PLY, compressed PLY, .splat, .spz, .sog, meta.json, .glb: docs/scene-formats.md), or "
                   "builtin:city?gaussians=N&seed=S")
        ->capture_default_str();
    app.add_option_function<std::string>(
           "--spz-axes",
           [&flags](std::string axes) {
               // IsMember checks without case but hands the word on as typed.
               std::transform(axes.begin(), axes.end(), axes.begin(), [](unsigned char c) { return std::tolower(c); });
               flags.spz_axes = axes == "rub" ? SpzAxes::rub : SpzAxes::rdf;
           },
           "the axes of a .spz file's data: rdf (as splat-transform writes it) or rub (as Niantic's spz library "
           "writes it; y and z are flipped on load)")
        ->check(CLI::IsMember({"rdf", "rub"}, CLI::ignore_case))
        ->default_str("rdf");
    app.add_flag("--drop-invalid", flags.drop_invalid,
                 "drop non-finite or zero-quaternion records instead of failing (stderr tells how many)");
}

Scene load_scene(const SceneFlags& flags, bool quiet) {
    LoadOptions load;
    load.spz_axes = flags.spz_axes;
    load.drop_invalid = flags.drop_invalid;
    load.progress = stderr_progress(!quiet);
    LoadReport report;
    Scene scene = catgs::load_scene(flags.scene, load, &report);
    if (!quiet && (report.dropped_invalid || report.dropped_transparent))
        std::cerr << "dropped " << report.dropped_invalid << " invalid and " << report.dropped_transparent
                  << " transparent (opacity < 1/255) Gaussians of " << report.records << "\n";
    return scene;
}

std::array<float, 3> parse_background(const std::string& text) {
    std::array<float, 3> rgb{};
    std::stringstream in(text);
    std::string part;
    int i = 0;
    while (std::getline(in, part, ',')) {
        if (i >= 3) throw Error("--background '" + text + "': expected three numbers r,g,b");
        try {
            std::size_t used = 0;
            rgb[i] = std::stof(part, &used);
            if (used != part.size()) throw std::invalid_argument(part);
        } catch (const std::exception&) {
            throw Error("--background '" + text + "': '" + part + "' is not a number");
        }
        if (!(rgb[i] >= 0.0f && rgb[i] <= 1.0f))
            throw Error("--background '" + text + "': each component must be in [0, 1]");
        ++i;
    }
    if (i != 3) throw Error("--background '" + text + "': expected three numbers r,g,b");
    return rgb;
}

std::vector<SweepEntry> parse_sweep(std::string text) {
    if (!text.empty() && text[0] == '@') {
        std::string problem;
        const std::optional<std::string> file = read_regular_file(text.substr(1), kMaxSmallFileBytes, problem);
        if (!file) throw Error("--sweep '" + text + "': cannot open the file: " + problem);
        text = *file;
        std::replace(text.begin(), text.end(), '\n', ';');
    }
    std::vector<SweepEntry> configs;
    std::stringstream in(text);
    std::string entry;
    while (std::getline(in, entry, ';')) {
        const auto first = entry.find_first_not_of(" \t\r\n");
        if (first == std::string::npos || entry[first] == '#') continue;
        const auto colon = entry.find(':');
        if (colon == std::string::npos) throw Error("--sweep entry '" + entry + "': expected 'name: flags'");
        SweepEntry c;
        c.name = entry.substr(first, colon - first);
        while (!c.name.empty() && std::isspace(static_cast<unsigned char>(c.name.back()))) c.name.pop_back();
        CLI::App app;
        PipelineFlags flags;
        add_pipeline_flags(app, flags);
        try {
            app.parse(entry.substr(colon + 1), false);
        } catch (const CLI::ExtrasError&) {
            // CLI11 lists the extras last first; name them as written, and what an entry takes.
            std::string extras, taken;
            for (const std::string& word : app.remaining()) extras += (extras.empty() ? "" : " ") + word;
            for (const CLI::Option* option : app.get_options())
                if (option->get_name() != "--help") taken += (taken.empty() ? "" : ", ") + option->get_name();
            throw Error("--sweep entry '" + c.name + "': '" + extras + "' is not a pipeline flag; an entry takes " +
                        taken + " (run-wide flags such as --precision, --backend or --width go before --sweep)");
        } catch (const CLI::ParseError& e) {
            throw Error("--sweep entry '" + c.name + "': " + e.what());
        }
        apply_pipeline_flags(flags, c.options);
        configs.push_back(c);
    }
    if (configs.empty()) throw Error("--sweep '" + text + "': no configurations");
    return configs;
}

}  // namespace catgs::cli
