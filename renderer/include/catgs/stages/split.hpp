// Tile task splitting (CaT-GS, supplementary Algorithm 1) and the merge of sub-task results.
//
// A tile whose depth-sorted list is longer than k becomes split_num + 1 sub-tasks, with
// split_num = floor(size / k): the first keeps size - split_num * k entries (the remainder,
// so the later sub-tasks, which are more often wasted behind an opaque front, are the full
// ones), each following sub-task takes k. Every sub-task blends its slice from T = 1 and
// keeps a partial colour R and transmittance A per pixel; the merge composites them front
// to back with (R1, A1) o (R2, A2) = (R1 + A1 R2, A1 A2), an associative operation, so
//   C = sum_i (prod_{j<i} A_j) R_i,  T = prod_i A_i,  pixel = C + T * background.
// The merge stops adding sub-tasks once the running T < 1e-4, as the unsplit blend would.
#pragma once

#include <cstdint>

#include "catgs/constants.hpp"
#include "catgs/hd.hpp"
#include "catgs/math.hpp"

namespace catgs {

/// Number of extra sub-tasks of a list of `size` entries (0: not split).
CATGS_INLINE std::uint32_t split_count(std::uint64_t size, std::uint32_t k) {
    return k == 0 || size <= k ? 0u : static_cast<std::uint32_t>(size / k);
}

/// [begin, end) of sub-task `index` (0 = the first, remainder-sized one) of the list
/// [list_begin, list_end), split with threshold k.
CATGS_INLINE void subtask_range(std::uint64_t list_begin, std::uint64_t list_end, std::uint32_t k, std::uint32_t index,
                                std::uint64_t& begin, std::uint64_t& end) {
    const std::uint64_t size = list_end - list_begin;
    const std::uint32_t splits = split_count(size, k);
    const std::uint64_t first = size - static_cast<std::uint64_t>(splits) * k;
    if (index == 0) {
        begin = list_begin;
        end = list_begin + first;
    } else {
        begin = list_begin + first + static_cast<std::uint64_t>(index - 1) * k;
        end = begin + k;
    }
}

/// The GPU's task order (not an image rule: any order draws the same pixels): an unsplit list
/// at least this many times the mean non-empty list runs right after the extra sub-tasks,
/// before the tiles in row order. Started in row order, such a list can start among the
/// frame's last tasks and finish alone, holding its band of rows back from the copy to the
/// host (a garden low 4K trace, session 32: the copy's exposed tail waited on such lists). 4 is
/// also where automatic k cuts a list (kAutoSplitFactor), so with splitting on it lists what
/// the floor of k left whole.
inline constexpr double kHeavyListFactor = 4.0;

/// Whether a list of `size` pairs runs first, in a frame of `pairs` pairs over `nonempty`
/// non-empty lists (kHeavyListFactor; 0 lists nothing).
CATGS_INLINE bool runs_first(std::uint64_t size, std::uint64_t pairs, std::uint32_t nonempty, double factor) {
    return factor > 0 && size > 0 && static_cast<double>(size) * nonempty >= factor * static_cast<double>(pairs);
}

/// One sub-task's result at a pixel: colour R (premultiplied, background excluded) and
/// transmittance A.
template <typename T>
struct Partial {
    Vec3<T> colour;
    T transmittance;
};

/// Front-to-back merge state of one pixel.
template <typename T>
struct MergeState {
    Vec3<T> colour{T(0), T(0), T(0)};
    T transmittance = T(1);
    bool done = false;
};

/// Adds the next sub-task (in split order) to the merge; once the running transmittance has
/// dropped below 1e-4, later sub-tasks are ignored.
template <typename T>
CATGS_INLINE void merge_partial(MergeState<T>& m, const Partial<T>& p) {
    if (m.done) return;
    const T t = m.transmittance;
    m.colour = {m.colour.x + t * p.colour.x, m.colour.y + t * p.colour.y, m.colour.z + t * p.colour.z};
    m.transmittance = t * p.transmittance;
    if (m.transmittance < static_cast<T>(kMinTransmittance)) m.done = true;
}

/// Adds the next shard's partial of a sharded frame, in the shards' front-to-back order
/// (sharded_renderer.hpp). A shard whose own blend stopped ends the composite: the unsharded
/// blend, whose transmittance there is at most the shard's, stopped at or before that point.
template <typename T>
CATGS_INLINE void merge_shard_partial(MergeState<T>& m, const Partial<T>& p, bool stopped) {
    merge_partial(m, p);
    m.done = m.done || stopped;
}

}  // namespace catgs
