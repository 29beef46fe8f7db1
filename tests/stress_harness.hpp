// The half of the numerical stress suite that does not depend on the backend: the pipeline
// configurations, how renders are measured against the exact double reference (held to its
// range where it is ill-conditioned: Reference) and logged,
// the bounds' vocabulary, the cases of the property tests, the crop comparison of the
// 8192 x 8192 tests, and what a backend provides (stress::Backend). tests/stress_suite.cpp
// runs the families and the property tests on every backend of the binary;
// tests/test_stress.cpp (CPU) and tests/gpu/test_cuda_stress.cpp (CUDA) define the backend,
// with its own bounds, which differ: the CPU runs double too, and the GPU's FMAs and exp move
// values at thresholds differently from the CPU's float. Definitions: stress_harness.cpp.
//
// A backend is named by its suite ("stress", "cuda stress"): its log lines start with
// "[suite]" and its seeds are labelled "suite what" (test::fresh_seed).
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "catgs/image.hpp"
#include "catgs/render_options.hpp"
#include "stress_scenes.hpp"

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
std::vector<Config> all_configs(bool with_double);

/// CaT-GS split threshold of the issue: short enough that every non-trivial tile splits.
inline constexpr std::uint32_t kSplitK = 8;
/// A background with every channel away from 0 and 1, so that errors in the final
/// transmittance show.
inline constexpr std::array<float, 3> kBackground{0.1f, 0.25f, 0.4f};

RenderOptions options_for(Culling culling, Mode mode);

std::size_t count_nonfinite(const ImageF& image);

struct Frame {
    ImageF image;
    ImageRGB8 rgb8;
    FrameStats stats;
};

// --- Measurements ---------------------------------------------------------------------

struct Reference;

struct Measured {
    int max_abs = 0;
    double min_psnr = std::numeric_limits<double>::infinity();
    double max_over_one = 0;  ///< largest fraction of channel values more than one level off
    std::size_t nonfinite = 0;
    /// Whether the backend wrote its 8-bit image itself (the GPU), so that it has to match
    /// the quantised float image; then `rgb8_mismatch` counts the values that do not.
    bool rgb8_checked = false;
    std::size_t rgb8_mismatch = 0;
    /// Channel values held to the reference's range rather than its exact value (Reference).
    std::size_t ill_conditioned = 0;
    int frames = 0, cached = 0;

    /// Adds a frame against its reference; `split`: a split render (Reference::split_low).
    void add(const Frame& f, const Reference& reference, bool split);
    void merge(const Measured& o);
};

/// The worst measurement per bound class (or per configuration), by name.
using Classes = std::map<std::string, Measured>;

std::string describe(const Measured& m);

inline std::string seed_note(std::uint64_t seed) {
    return "(CATGS_TEST_SEED=" + std::to_string(seed) + ")";
}

void report(const std::string& suite, const std::string& what, const Classes& classes);

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

const char* bound_class_name(BoundClass k);

/// A cached frame against the same configuration rendered in full by the same backend:
/// identical lists in exact and opacity-aware culling (one level for the regrouped sums), but
/// bbox3sigma lists are grown by the guard band on key frames, so a cached bbox3sigma frame
/// draws more of the cut 3-sigma tails than the full one (measured up to 7 levels). A missing
/// Gaussian is ~200.
inline int cache_vs_full_levels(Culling culling) {
    return culling == Culling::bbox3sigma ? 10 : 1;
}

/// The checks every backend makes of a configuration's measurement against its bound.
/// `small_image`: a handful of pixels, where one value one level off already means a PSNR of
/// 53 dB and a fraction of 33%: only the largest difference is checked.
void expect_within(const Measured& m, const Bound& b, bool small_image, const std::string& what);

// --- Large images ---------------------------------------------------------------------

/// The largest difference between a `size` x `size` image, whose i-th channel value is
/// `level(i)` in 8 bits, and `crop`, the reference rendered for its pixels `box` (crop_camera).
/// Marks those pixels in `covered` (size x size), so that the rest can be checked against the
/// background.
template <typename Level>
int worst_in_crop(int size, Level level, const std::array<int, 4>& box, const ImageRGB8& crop,
                  std::vector<bool>& covered) {
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

// --- Backends -------------------------------------------------------------------------

/// What the shared suite needs of a backend: its configurations, their bounds per family, and
/// how it renders a case. Each test binary defines stress_backends() with the backends it
/// holds (catgs_tests the CPU, catgs_gpu_tests CUDA), so that CI runs the CPU families once.
class Backend {
public:
    virtual ~Backend() = default;
    /// "cpu", "cuda": the suffix of the test names.
    virtual std::string name() const = 0;
    /// "stress", "cuda stress": log lines start with "[suite]", seeds are labelled "suite what".
    virtual std::string suite() const = 0;
    /// Why the backend cannot render here (no device); empty when it can.
    virtual std::string unavailable() const { return {}; }
    virtual std::vector<Config> configs() const = 0;
    /// The configuration as failures and the measurement name it.
    virtual std::string config_name(const Config& cfg) const { return cfg.name(); }
    /// The class of bound the configuration is held to, the key of the reports.
    virtual std::string class_label(const Config& cfg) const = 0;
    virtual Bound bound_for(Family f, const Config& cfg) const = 0;
    /// Frame 0 of the case's path (plain, split), or the whole path through one renderer
    /// (cache: the frames after a key frame may come from the cache).
    virtual std::vector<Frame> render(const StressCase& c, const Config& cfg) const = 0;
    /// Whether render() writes the 8-bit image itself (the GPU quantises on the device), so
    /// that it has to match the quantised float image.
    virtual bool writes_rgb8() const { return false; }
};

/// The backends of this test binary, by name; defined by the binary's backend file.
const std::vector<const Backend*>& stress_backends();
std::vector<std::string> stress_backend_names();
const Backend& stress_backend(const std::string& name);

/// The exact double reference (CpuRenderer<double>, exact culling, no split, no cache) of one
/// camera.
Frame reference_frame(const Scene& scene, const Camera& camera);

/// The relative change of every opacity by which the reference is probed for values that
/// rounding may move by more than one level: about 100 times float's rounding of an alpha
/// (its exp and its power, ~1e-6 relative), and far below any error the bounds look for. An
/// alpha that lands within it of 1/255 moves a value by up to its colour times T / 255, a
/// transmittance within it of the 1e-4 stop by its colour times alpha times 1e-4; with the
/// clamped colours of huge SH (up to kMaxShColour = 1e4) either can be full scale, and float
/// and double then disagree by up to 255 levels at that value without either being wrong
/// (CATGS_TEST_SEED=13205819217021527008, huge sh: 93 levels at one value;
/// 8412562199189686241, extreme sh: 229).
inline constexpr double kConditioningOpacity = 1e-4;

/// The reference of one frame and how well conditioned each of its 8-bit channel values is.
/// `low` and `high` hold, per value, the least and greatest of the exact reference and of the
/// reference with every opacity scaled by 1 -+ kConditioningOpacity. A value whose range spans
/// more than one level is ill-conditioned: a render is held to that range there, and to the
/// exact value everywhere else (so the thresholds' one-level moves stay checked exactly).
/// The logs count such values ("N ill-conditioned", summed over the frames measured): over 169
/// seeds of every family and 22 of the property tests, none in the families without colours
/// above 1, and in the worst run 100 over 42 frames of 8640 values (100 further property-test
/// seeds failed nothing). No bound is set on that count: a Gaussian of opacity 1/255 + 1 ulp,
/// colour 1e4 and a screen-filling footprint makes a whole disc ill-conditioned without any
/// renderer being wrong.
///
/// A split render (CaT-GS, stages/split.hpp) is held to a wider range where the exact blend
/// stopped: every sub-task blends from T = 1, so only the merge sees the pixel's transmittance,
/// and the split draws the rest of the sub-task in which the plain blend stopped (a sub-task's
/// own stop implies the plain one at or before it). It draws a longer prefix of the same list,
/// whose extra Gaussians weigh sum(alpha_i T_i) <= T_stop (the transmittance the plain blend
/// stopped at, < 1e-2), each of colour c_i in [0, c_max]: the value moves by T_stop (c_i - bg),
/// within [exact - T_stop bg, exact + T_stop (c_max - bg)]. With colours <= 1 that is under 3
/// levels; with the clamped colours of huge SH it is full scale wherever such a Gaussian lies
/// behind a stop (CATGS_TEST_SEED=9449315962251313146, hdr mixture 5: 127 levels on 4.2% of
/// the values of the double split, past the fraction 240 earlier seeds had bounded). Where
/// the plain blend did not stop, the split draws the same list and is held as any render.
struct Reference {
    Frame exact;
    ImageRGB8 low, high;
    /// low and high widened by the split's range where the exact blend stopped.
    ImageRGB8 split_low, split_high;

    bool ill_conditioned(std::size_t i) const { return high.rgb[i] - low.rgb[i] > 1; }
    std::size_t ill_conditioned_count() const;
    /// The image `image` is compared with: the exact reference, with each value whose range
    /// spans more than one level (low..high, or split_low..split_high for a split render)
    /// replaced by the nearest value of that range to `image`'s.
    ImageRGB8 target_for(const ImageRGB8& image, bool split = false) const;
};

/// The largest colour channel (SH clamped to [0, kMaxShColour]) of any Gaussian of the scene
/// seen from `camera`: c_max of the split's range (Reference).
double largest_colour(const Scene& scene, const Camera& camera);

/// The reference of every frame of a case's path.
std::vector<Reference> reference_frames(const StressCase& c);

/// A backend's frames against the reference frames of the same path; `split`: rendered with
/// the split (Reference).
Measured measure(const Backend& backend, const std::vector<Frame>& frames, const std::vector<Reference>& reference,
                 bool split);

/// Renders every configuration of the case, checks each against the family's bound (failures
/// carry `note`) and returns the worst measurement per bound class.
/// `small_image`: see expect_within.
Classes check_case(const Backend& backend, const StressCase& c, const std::string& note, bool small_image);

/// One family case for a fresh seed, reported per bound class.
void run_family(const Backend& backend, const FamilyGenerator& family);

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

std::vector<LabelledCase> mixture_cases(std::uint64_t seed);
std::vector<LabelledCase> field_of_view_cases(std::uint64_t seed);
std::vector<LabelledCase> resolution_cases(std::uint64_t seed);

/// Every case of `cases(seed)` for a fresh seed; reports the worst per bound class of each
/// group, the groups in the order they first appear.
void run_cases(const Backend& backend, const std::string& what, std::vector<LabelledCase> (*cases)(std::uint64_t));

/// DISABLED_MeasureBounds: every configuration of every family and four fields of view, over
/// CATGS_STRESS_SEEDS seeds (default 20) from a fresh one; prints the worst per family and
/// bound class and per family and configuration.
void measure_bounds(const Backend& backend);

}  // namespace catgs::test::stress
