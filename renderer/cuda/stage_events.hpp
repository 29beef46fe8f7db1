// CUDA events around the stages of one frame, and the stage times read from them into
// FrameStats::stage_ms. The events are recorded on the renderer's stream, so a stage's time
// is GPU time between its neighbours' marks, without host synchronisation in between.
#pragma once

#include <cuda_runtime_api.h>

#include <array>
#include <cstddef>

#include "catgs/stage.hpp"
#include "cuda_check.hpp"

namespace catgs::cuda {

/// The marks of one frame on the stream. A banded frame marks band_count..rasterize once per band,
/// and each band's are read once it is drawn; rasterize runs from `split`, with no host wait
/// between them.
enum class Event : int {
    start,
    chunk_cull,
    preprocess,
    depth_order,  // sort's first part, before scan: the Gaussians front to back (sort.cuh)
    scan,
    band_count,
    band_scan,
    keys,
    sort,
    ranges,
    split,
    rasterize,  // merge too: split tiles are merged inside rasterize (merge.cuh)
    copy_out,   // the copy stream's last copy, seen from the renderer's stream
};
inline constexpr std::size_t kEventCount = 13;

class StageEvents {
public:
    StageEvents() {
        for (auto& e : events_) CATGS_CUDA_CHECK(cudaEventCreate(&e));
    }
    ~StageEvents() {
        for (auto& e : events_) cudaEventDestroy(e);  // not checked: runs in destructors
    }
    StageEvents(const StageEvents&) = delete;
    StageEvents& operator=(const StageEvents&) = delete;

    /// Starts a frame: every stage time back to 0.
    void clear() { ms_ = {}; }

    void record(Event event, cudaStream_t stream) { CATGS_CUDA_CHECK(cudaEventRecord(at(event), stream)); }
    void synchronize(Event event) { CATGS_CUDA_CHECK(cudaEventSynchronize(at(event))); }

    /// Adds the time from `from` to `to` (both recorded and complete) to `stage`.
    void add(Stage stage, Event from, Event to) {
        float ms = 0;
        CATGS_CUDA_CHECK(cudaEventElapsedTime(&ms, at(from), at(to)));
        ms_[static_cast<std::size_t>(stage)] += ms;
    }

    /// The frame's stage times; the stages this backend never marks stay 0.
    void write(StageTimes& out) const {
        for (std::size_t s = 0; s < kStageCount; ++s) out.ms[s] = ms_[s];
    }

private:
    cudaEvent_t at(Event event) const { return events_[static_cast<std::size_t>(event)]; }

    std::array<cudaEvent_t, kEventCount> events_{};
    std::array<float, kStageCount> ms_{};
};

}  // namespace catgs::cuda
