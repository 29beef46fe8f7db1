// The pipeline's stages, in the order a frame runs them. Each stage has this one name in the
// code of both backends, in FrameStats, in the tools' tables and JSON (`<name>_ms`), in the
// server's logs and in the docs, so a number can be traced to the code that produced it.
#pragma once

#include <array>
#include <cstddef>
#include <string_view>

namespace catgs {

enum class Stage : int {
    chunk_cull,  ///< skip the scene's chunks that no pose of the frame can see (stages/chunks.hpp)
    preprocess,  ///< per Gaussian: cull, project, conic, SH colour, tile count (stages/project.hpp)
    scan,        ///< exclusive prefix sum of the tile counts: where each Gaussian's keys go
    keys,        ///< one (tile | depth) sort key per tile-Gaussian pair (stages/keys.hpp)
    sort,        ///< the pairs ordered by key: by tile, then front to back
    ranges,      ///< each tile's [begin, end) in the sorted pairs
    split,       ///< the task list: CaT-GS Algorithm 1 cuts lists longer than k (stages/split.hpp)
    rasterize,   ///< each task blends its Gaussians front to back per pixel (stages/blend.hpp)
    merge,       ///< split tiles: partial colour and transmittance composited front to back (on the
                 ///< GPU inside rasterize, by each split tile's last sub-task: no time of its own)
    copy_out,    ///< the image to host memory (GPU backend)
    encode,      ///< the image to JPEG, PNG or raw bytes (server)
};

inline constexpr std::size_t kStageCount = 11;

inline constexpr std::array<Stage, kStageCount> kStages{
    Stage::chunk_cull, Stage::preprocess, Stage::scan,  Stage::keys,     Stage::sort,   Stage::ranges,
    Stage::split,      Stage::rasterize,  Stage::merge, Stage::copy_out, Stage::encode,
};

constexpr std::string_view stage_name(Stage stage) {
    switch (stage) {
        case Stage::chunk_cull:
            return "chunk_cull";
        case Stage::preprocess:
            return "preprocess";
        case Stage::scan:
            return "scan";
        case Stage::keys:
            return "keys";
        case Stage::sort:
            return "sort";
        case Stage::ranges:
            return "ranges";
        case Stage::split:
            return "split";
        case Stage::rasterize:
            return "rasterize";
        case Stage::merge:
            return "merge";
        case Stage::copy_out:
            return "copy_out";
        case Stage::encode:
            return "encode";
    }
    return "unknown";
}

/// Milliseconds per stage of one frame; a stage a frame does not run (or a backend folds into
/// another, as each names) stays 0.
struct StageTimes {
    std::array<double, kStageCount> ms{};

    double& operator[](Stage stage) { return ms[static_cast<std::size_t>(stage)]; }
    double operator[](Stage stage) const { return ms[static_cast<std::size_t>(stage)]; }
    double sum() const {
        double total = 0;
        for (double v : ms) total += v;
        return total;
    }
};

}  // namespace catgs
