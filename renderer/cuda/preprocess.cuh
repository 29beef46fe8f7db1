// preprocess: per Gaussian of the live chunks, cull, project, conic, SH colour and the count
// of the tiles it touches over the window; key frames of the cache also reduce what the frame
// planner needs. reproject is the cached frames' preprocess: the cached Gaussians projected
// again at the actual pose.
#pragma once

#include <cuda_runtime_api.h>

#include <cstdint>

#include "catgs/stages/culling.hpp"
#include "catgs/stages/project.hpp"
#include "catgs/stages/view.hpp"
#include "kernel_common.cuh"
#include "occlusion.cuh"

namespace catgs::cuda {

template <typename T>
struct PreprocessArgs {
    DeviceSceneView scene;
    ChunkSpace space;
    const View<T>* views;  // the window's poses, with the (maybe lowered) near plane
    int window;
    View<T> actual;         // the pose the frame is rendered at
    bool reproject_actual;  // the window lowered the near plane: project the actual pose again
    Culling culling;
    T guard, guard_translation;
    bool summarize;           // reduce nearest depth, inverse depth and extent (a cached window)
    Projected<T>* projected;  // by Gaussian
    std::uint64_t* touched;   // by slot, plus the trailing 0 the scan needs
    float* sort_depth;        // by slot
    FrameCounters* counters;
    /// A plain single-pose frame's occlusion cut (stages/occlusion.hpp): the Gaussians behind it
    /// count no tiles. Inactive for windows, whose lists serve other poses.
    OcclusionCut occlusion{};
};

template <typename T>
void preprocess(const PreprocessArgs<T>& args, cudaStream_t stream);

template <typename T>
struct ReprojectArgs {
    DeviceSceneView scene;
    ChunkSpace space;  // the key frame's
    View<T> actual;
    const std::uint64_t* touched;  // the key frame's counts: 0 = not in the lists
    Projected<T>* projected;
    FrameCounters* counters;
};

template <typename T>
void reproject(const ReprojectArgs<T>& args, cudaStream_t stream);

}  // namespace catgs::cuda
