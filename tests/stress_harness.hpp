// The half of the numerical stress suite that does not depend on the backend: the pipeline
// configurations, how renders are measured against the exact double reference and logged,
// the cases of the property tests and the loops that run them, and the crop comparison of
// the 8192 x 8192 tests. tests/test_stress.cpp (CPU) and tests/gpu/test_cuda_stress.cpp
// (CUDA) add how their backend renders a case and their own bounds, which differ: the CPU
// runs double too, and the GPU's FMAs and exp move values at thresholds differently from the
// CPU's float.
//
// A backend is named by its suite ("stress", "cuda stress"): its log lines start with
// "[suite]" and its seeds are labelled "suite what" (test::fresh_seed).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "catgs/cache.hpp"
#include "catgs/image.hpp"
#include "catgs/render_options.hpp"
#include "stress_scenes.hpp"
#include "test_util.hpp"

namespace catgs::test::stress {

// --- Configurations -------------------------------------------------------------------

enum class Mode { plain, split, cache };

struct Config {
    bool use_double;
    Culling culling;
    Mode mode;
    std::string name() const {
        std::string n = use_double ? "double " : "float ";
        n += culling_name(culling);
        if (mode == Mode::split) n += " split8";
        if (mode == Mode::cache) n += " cache";
        return n;
    }
};

/// Every configuration in float, and with `with_double` in double too, except the reference
/// itself (double, exact, plain).
inline std::vector<Config> all_configs(bool with_double) {
    std::vector<Config> out;
    for (bool d : {false, true}) {
        if (d && !with_double) break;
        for (Culling c : {Culling::exact, Culling::bbox3sigma, Culling::opacity_aware})
            for (Mode m : {Mode::plain, Mode::split, Mode::cache}) {
                if (d && c == Culling::exact && m == Mode::plain) continue;
                out.push_back({d, c, m});
            }
    }
    return out;
}

/// CaT-GS split threshold of the issue: short enough that every non-trivial tile splits.
inline constexpr std::uint32_t kSplitK = 8;
/// A background with every channel away from 0 and 1, so that errors in the final
/// transmittance show.
inline constexpr std::array<float, 3> kBackground{0.1f, 0.25f, 0.4f};

inline RenderOptions options_for(Culling culling, Mode mode) {
    RenderOptions o;
    o.culling = culling;
    o.background = kBackground;
    if (mode == Mode::split) o.catgs.split_k = kSplitK;
    if (mode == Mode::cache) o.catgs.cache = CacheMode::speculative;
    return o;
}

inline std::size_t count_nonfinite(const ImageF& image) {
    return static_cast<std::size_t>(
        std::count_if(image.rgb.begin(), image.rgb.end(), [](float v) { return !std::isfinite(v); }));
}

struct Frame {
    ImageF image;
    ImageRGB8 rgb8;
    FrameStats stats;
};

// --- Measurements ---------------------------------------------------------------------

struct Measured {
    int max_abs = 0;
    double min_psnr = std::numeric_limits<double>::infinity();
    double max_over_one = 0;  ///< largest fraction of channel values more than one level off
    std::size_t nonfinite = 0;
    /// Whether the backend wrote its 8-bit image itself (the GPU), so that it has to match
    /// the quantised float image; then `rgb8_mismatch` counts the values that do not.
    bool rgb8_checked = false;
    std::size_t rgb8_mismatch = 0;
    int frames = 0, cached = 0;

    /// Adds a frame against its reference image.
    void add(const Frame& f, const ImageRGB8& reference) {
        const ImageError e = compare(f.rgb8, reference);
        max_abs = std::max(max_abs, e.max_abs);
        min_psnr = std::min(min_psnr, e.psnr);
        max_over_one = std::max(max_over_one, e.fraction_over_one);
        nonfinite += count_nonfinite(f.image);
        ++frames;
        cached += !f.stats.key_frame;
    }

    void merge(const Measured& o) {
        max_abs = std::max(max_abs, o.max_abs);
        min_psnr = std::min(min_psnr, o.min_psnr);
        max_over_one = std::max(max_over_one, o.max_over_one);
        nonfinite += o.nonfinite;
        rgb8_checked = rgb8_checked || o.rgb8_checked;
        rgb8_mismatch += o.rgb8_mismatch;
        frames += o.frames;
        cached += o.cached;
    }
};

/// The worst measurement per bound class (or per configuration), by name.
using Classes = std::map<std::string, Measured>;

inline std::string describe(const Measured& m) {
    std::ostringstream s;
    s << "max " << m.max_abs << " levels, psnr " << std::fixed << std::setprecision(1) << m.min_psnr << " dB, "
      << std::setprecision(4) << 100 * m.max_over_one << "% > 1 level, " << m.nonfinite << " non-finite, ";
    if (m.rgb8_checked) s << m.rgb8_mismatch << " rgb8 != quantised float, ";
    s << m.cached << "/" << m.frames << " cached";
    return s.str();
}

inline std::string seed_note(std::uint64_t seed) { return "(CATGS_TEST_SEED=" + std::to_string(seed) + ")"; }

inline void report(const std::string& suite, const std::string& what, const Classes& classes) {
    for (const auto& [name, m] : classes)
        std::cout << "[" << suite << "] " << what << ", " << name << ": " << describe(m) << std::endl;
}

// --- Bounds ---------------------------------------------------------------------------

/// An error bound against the exact double reference: the largest 8-bit difference of any
/// channel, the lowest PSNR of any frame, and the largest fraction of channel values that
/// differ by more than one level.
struct Bound {
    int max_levels;
    double min_psnr;
    double max_over_one;
};

/// The classes of configuration that the bounds tell apart (test_stress.cpp says why each
/// errs as it does); a backend may split them further by precision.
enum class BoundClass { lossless, split, bbox3sigma };

/// bbox3sigma culling is lossy in any mode; otherwise the split is; what remains is lossless.
inline BoundClass bound_class(const Config& cfg) {
    if (cfg.culling == Culling::bbox3sigma) return BoundClass::bbox3sigma;
    return cfg.mode == Mode::split ? BoundClass::split : BoundClass::lossless;
}

inline const char* bound_class_name(BoundClass k) {
    switch (k) {
        case BoundClass::lossless: return "lossless";
        case BoundClass::split: return "split";
        case BoundClass::bbox3sigma: return "bbox3sigma";
    }
    return "?";
}

/// A cached frame against the same configuration rendered in full by the same backend:
/// identical lists in exact and opacity-aware culling (one level for the regrouped sums), but
/// bbox3sigma lists are grown by the guard band on key frames, so a cached bbox3sigma frame
/// draws more of the cut 3-sigma tails than the full one (measured up to 7 levels). A missing
/// Gaussian is ~200.
inline int cache_vs_full_levels(Culling culling) { return culling == Culling::bbox3sigma ? 10 : 1; }

/// The checks every backend makes of a configuration's measurement against its bound.
/// `small_image`: a handful of pixels, where one value one level off already means a PSNR of
/// 53 dB and a fraction of 33%: only the largest difference is checked.
inline void expect_within(const Measured& m, const Bound& b, bool small_image, const std::string& what) {
    EXPECT_EQ(m.nonfinite, 0u) << what;
    EXPECT_LE(m.max_abs, b.max_levels) << what;
    if (!small_image) {
        EXPECT_GE(m.min_psnr, b.min_psnr) << what;
        EXPECT_LE(m.max_over_one, b.max_over_one) << what;
    }
}

// --- Large images ---------------------------------------------------------------------

/// The largest difference between a `size` x `size` image, whose i-th channel value is
/// `level(i)` in 8 bits, and `crop`, the reference rendered for its pixels `box` (crop_camera).
/// Marks those pixels in `covered` (size x size), so that the rest can be checked against the
/// background.
template <typename Level>
int worst_in_crop(int size, Level level, const std::array<int, 4>& box, const ImageRGB8& crop, std::vector<bool>& covered) {
    const auto [x0, y0, x1, y1] = box;
    int worst = 0;
    for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
            covered[static_cast<std::size_t>(y) * size + x] = true;
            for (int ch = 0; ch < 3; ++ch) {
                const int a = level(3 * (static_cast<std::size_t>(y) * size + x) + ch);
                const int b = crop.rgb[3 * (static_cast<std::size_t>(y - y0) * (x1 - x0) + (x - x0)) + ch];
                worst = std::max(worst, std::abs(a - b));
            }
        }
    return worst;
}

// --- Running cases --------------------------------------------------------------------
// `check` is a backend's check_case(case, note, small_image): it renders every configuration
// of the case, checks each against the case family's bounds (failures carry `note`) and
// returns the worst measurement per bound class.

/// One family case for a fresh seed.
template <typename Check>
void run_family(const std::string& suite, Check check, StressCase (*make)(std::uint64_t), const std::string& what) {
    const std::uint64_t seed = test::fresh_seed(suite + " " + what);
    const StressCase c = make(seed);
    report(suite, c.name, check(c, seed_note(seed), false));
}

/// A case of a property test: the note its failures carry (the seed that replays it, which
/// case it is), the group whose worst it is reported under, and whether its image is too
/// small for PSNR and fractions to say anything (expect_within).
struct LabelledCase {
    StressCase c;
    std::string note;
    std::string group;
    bool small_image = false;
};

/// Mixtures per run: every adversarial kind at random in one scene; one in three with SH
/// colours of 1e30.
inline constexpr int kMixtureSeeds = 9;

inline std::vector<LabelledCase> mixture_cases(std::uint64_t seed) {
    std::vector<LabelledCase> out;
    for (int k = 0; k < kMixtureSeeds; ++k) {
        const bool hdr = k % 3 == 2;
        out.push_back({mixture(seed + 1000003ull * static_cast<std::uint64_t>(k), 150, hdr),
                       seed_note(seed) + " mixture " + std::to_string(k), hdr ? "hdr mixtures" : "mixtures"});
    }
    return out;
}

inline std::vector<LabelledCase> field_of_view_cases(std::uint64_t seed) {
    std::vector<LabelledCase> out;
    for (double fov : {5.0, 10.0, 30.0, 60.0, 90.0, 120.0, 150.0})
        out.push_back({field_of_view(seed + static_cast<std::uint64_t>(fov), fov), seed_note(seed) + " fov " + std::to_string(fov),
                       "fov 5..150"});
    return out;
}

inline std::vector<LabelledCase> resolution_cases(std::uint64_t seed) {
    std::vector<LabelledCase> out;
    for (auto [w, h] : {std::pair{1, 1}, std::pair{1, 2}, std::pair{2, 1}, std::pair{1, 37}, std::pair{45, 1},
                        std::pair{15, 17}, std::pair{16, 16}, std::pair{17, 17}, std::pair{255, 3}, std::pair{3, 129}}) {
        StressCase c = mixture(seed + static_cast<std::uint64_t>(w * 1000 + h), 120);
        c.path = sideways_path(test::forward_camera(w, h, 60));  // see mixture()
        // Square pixels and a 60 degree horizontal field: 3 x 129 sees 175 degrees vertically,
        // so the field-of-view bounds apply; on slivers PSNR and fractions say little.
        c.family = Family::field_of_view;
        out.push_back({std::move(c), seed_note(seed) + " " + std::to_string(w) + "x" + std::to_string(h),
                       "resolutions 1x1..255x3", w * h < 256 || std::min(w, h) < 8});
    }
    return out;
}

/// Every case of `cases(seed)` for a fresh seed; reports the worst per bound class of each
/// group, the groups in the order they first appear.
template <typename Check>
void run_cases(const std::string& suite, const std::string& what, std::vector<LabelledCase> (*cases)(std::uint64_t),
               Check check) {
    const std::uint64_t seed = test::fresh_seed(suite + " " + what);
    std::vector<std::pair<std::string, Classes>> groups;
    for (const LabelledCase& lc : cases(seed)) {
        auto group = std::find_if(groups.begin(), groups.end(), [&](const auto& g) { return g.first == lc.group; });
        if (group == groups.end()) group = groups.emplace(groups.end(), lc.group, Classes{});
        for (const auto& [name, m] : check(lc.c, lc.note, lc.small_image)) group->second[name].merge(m);
    }
    for (const auto& [group, worst] : groups) report(suite, group, worst);
}

/// DISABLED_MeasureBounds: `measure_case(case, worst)` for every family and four fields of
/// view, over CATGS_STRESS_SEEDS seeds (default 20) from a fresh one; prints the worst by name.
template <typename MeasureCase>
void measure_bounds(const std::string& suite, MeasureCase measure_case) {
    const char* env = std::getenv("CATGS_STRESS_SEEDS");
    const int seeds = env ? std::atoi(env) : 20;
    const std::uint64_t base = test::fresh_seed(suite + " measure");
    Classes worst;
    for (int s = 0; s < seeds; ++s) {
        const std::uint64_t seed = base + static_cast<std::uint64_t>(s) * 7919;
        std::vector<StressCase> cases = all_families(seed);
        for (double fov : {5.0, 20.0, 90.0, 150.0}) cases.push_back(field_of_view(seed + static_cast<std::uint64_t>(fov), fov));
        for (const StressCase& c : cases) measure_case(c, worst);
    }
    for (const auto& [name, m] : worst) std::cout << "[measure] " << name << ": " << describe(m) << std::endl;
}

}  // namespace catgs::test::stress
