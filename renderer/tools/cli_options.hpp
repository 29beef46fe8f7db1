// Command-line flags and values shared by catgs-render and catgs-bench: the pipeline options,
// parsed the same way in both, so a configuration benchmarked is one that can be rendered,
// and the free-text values the tools parse (--background, --sweep). Library code (catgs_cli),
// so that the fuzz targets of tests/fuzz call the parsers the tools call.
#pragma once

#include <CLI/CLI.hpp>

#include <array>
#include <utility>
#include <string>
#include <vector>

#include "catgs/render_options.hpp"
#include "catgs/scene_io.hpp"

namespace catgs::cli {

/// The flags' values, as text where a flag takes words; they start as
/// default_pipeline_options(), so `--help` shows the defaults every tool and the server share.
struct PipelineFlags {
    explicit PipelineFlags(const RenderOptions& o = default_pipeline_options());

    std::string culling, split;
    double split_tail;
    std::string cache, window;
    int window_start;
    std::string window_cost;
    double guard_px, guard_m;
    std::string resort, chunks, reuse_order_max_deg, occlusion_cut;

    /// Degrees as the flag shows them; "any" for no limit.
    static std::string angle_name(double radians);
};

void add_pipeline_flags(CLI::App& app, PipelineFlags& f);

/// Applies the flags to `options`; throws catgs::Error naming the flag and value.
void apply_pipeline_flags(const PipelineFlags& f, RenderOptions& options);

/// A short description of the pipeline options for logs and benchmark tables.
std::string describe_pipeline(const RenderOptions& o);

/// --scene (a file of any format, or a builtin spec), --spz-axes (the axes a .spz file's data is
/// in: the format has no field for it) and --drop-invalid, as catgs-render and catgs-bench take them.
struct SceneFlags {
    explicit SceneFlags(std::string default_scene) : scene(std::move(default_scene)) {}
    std::string scene;
    SpzAxes spz_axes = SpzAxes::rdf;
    bool drop_invalid = false;
};

void add_scene_flags(CLI::App& app, SceneFlags& flags);

/// Loads --scene as the flags say, with progress on stderr unless `quiet`; what was dropped
/// (invalid records under --drop-invalid, transparent ones always) is told on stderr unless
/// `quiet`, so a benchmark never times a scene smaller than the file without saying so.
Scene load_scene(const SceneFlags& flags, bool quiet);

/// catgs-render's --background "r,g,b", each in [0, 1]; throws catgs::Error naming the flag.
std::array<float, 3> parse_background(const std::string& text);

/// One configuration of catgs-bench's --sweep.
struct SweepEntry {
    std::string name;
    RenderOptions options = default_pipeline_options();
};

/// Parses "name: flags; name: flags" (or one "name: flags" per line of @file) into entries,
/// each entry's flags applied over the defaults; throws catgs::Error naming the entry.
std::vector<SweepEntry> parse_sweep(std::string text);

}  // namespace catgs::cli
