// The backend-neutral half of the stress suite, documented in stress_harness.hpp.
#include "stress_harness.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "catgs/cache.hpp"
#include "catgs/cpu_renderer.hpp"
#include "catgs/stages/blend.hpp"
#include "catgs/stages/sh.hpp"
#include "test_util.hpp"

namespace catgs::test::stress {

std::vector<Config> all_configs(bool with_double) {
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

RenderOptions options_for(Culling culling, Mode mode) {
    RenderOptions o;
    o.culling = culling;
    o.background = kBackground;
    if (mode == Mode::split) o.catgs.split_k = kSplitK;
    if (mode == Mode::cache) o.catgs.cache = CacheMode::speculative;
    return o;
}

std::size_t count_nonfinite(const ImageF& image) {
    return static_cast<std::size_t>(
        std::count_if(image.rgb.begin(), image.rgb.end(), [](float v) { return !std::isfinite(v); }));
}

void Measured::add(const Frame& f, const Reference& reference, bool split) {
    const ImageError e = compare(f.rgb8, reference.target_for(f.rgb8, split));
    ill_conditioned += reference.ill_conditioned_count();
    max_abs = std::max(max_abs, e.max_abs);
    min_psnr = std::min(min_psnr, e.psnr);
    max_over_one = std::max(max_over_one, e.fraction_over_one);
    nonfinite += count_nonfinite(f.image);
    ++frames;
    cached += !f.stats.key_frame;
}

void Measured::merge(const Measured& o) {
    max_abs = std::max(max_abs, o.max_abs);
    min_psnr = std::min(min_psnr, o.min_psnr);
    max_over_one = std::max(max_over_one, o.max_over_one);
    nonfinite += o.nonfinite;
    rgb8_checked = rgb8_checked || o.rgb8_checked;
    rgb8_mismatch += o.rgb8_mismatch;
    ill_conditioned += o.ill_conditioned;
    frames += o.frames;
    cached += o.cached;
}

std::string describe(const Measured& m) {
    std::ostringstream s;
    s << "max " << m.max_abs << " levels, psnr " << std::fixed << std::setprecision(1) << m.min_psnr << " dB, "
      << std::setprecision(4) << 100 * m.max_over_one << "% > 1 level, " << m.nonfinite << " non-finite, ";
    if (m.rgb8_checked) s << m.rgb8_mismatch << " rgb8 != quantised float, ";
    if (m.ill_conditioned > 0) s << m.ill_conditioned << " ill-conditioned, ";
    s << m.cached << "/" << m.frames << " cached";
    return s.str();
}

void report(const std::string& suite, const std::string& what, const Classes& classes) {
    for (const auto& [name, m] : classes)
        std::cout << "[" << suite << "] " << what << ", " << name << ": " << describe(m) << std::endl;
}

const char* bound_class_name(BoundClass k) {
    switch (k) {
        case BoundClass::lossless:
            return "lossless";
        case BoundClass::split:
            return "split";
        case BoundClass::bbox3sigma:
            return "bbox3sigma";
    }
    return "?";
}

void expect_within(const Measured& m, const Bound& b, bool small_image, const std::string& what) {
    EXPECT_EQ(m.nonfinite, 0u) << what;
    EXPECT_LE(m.max_abs, b.max_levels) << what;
    if (!small_image) {
        EXPECT_GE(m.min_psnr, b.min_psnr) << what;
        EXPECT_LE(m.max_over_one, b.max_over_one) << what;
    }
}

// --- Backends -------------------------------------------------------------------------

std::vector<std::string> stress_backend_names() {
    std::vector<std::string> names;
    for (const Backend* b : stress_backends()) names.push_back(b->name());
    return names;
}

const Backend& stress_backend(const std::string& name) {
    for (const Backend* b : stress_backends())
        if (b->name() == name) return *b;
    throw std::invalid_argument("no stress backend '" + name + "' in this binary");
}

Frame reference_frame(const Scene& scene, const Camera& camera) {
    CpuRenderer<double> renderer;
    Frame f;
    f.stats = renderer.render(scene, camera, options_for(Culling::exact, Mode::plain), f.image);
    f.rgb8 = to_rgb8(f.image);
    return f;
}

std::size_t Reference::ill_conditioned_count() const {
    std::size_t n = 0;
    for (std::size_t i = 0; i < exact.rgb8.rgb.size(); ++i) n += ill_conditioned(i);
    return n;
}

ImageRGB8 Reference::target_for(const ImageRGB8& image, bool split) const {
    ImageRGB8 target = exact.rgb8;
    if (image.rgb.size() != target.rgb.size()) return target;  // compare() reports the sizes
    const ImageRGB8& lo = split ? split_low : low;
    const ImageRGB8& hi = split ? split_high : high;
    for (std::size_t i = 0; i < target.rgb.size(); ++i)
        if (hi.rgb[i] - lo.rgb[i] > 1) target.rgb[i] = std::clamp(image.rgb[i], lo.rgb[i], hi.rgb[i]);
    return target;
}

double largest_colour(const Scene& scene, const Camera& camera) {
    const std::array<double, 3> world = camera_centre(camera.pose);
    const Vec3<double> centre{world[0] - scene.origin[0], world[1] - scene.origin[1], world[2] - scene.origin[2]};
    const std::size_t stride = 3u * static_cast<std::size_t>(scene.sh_coefficients());
    double largest = 0;
    for (std::size_t g = 0; g < scene.count(); ++g) {
        Vec3<double> dir{scene.positions[3 * g] - centre.x, scene.positions[3 * g + 1] - centre.y,
                         scene.positions[3 * g + 2] - centre.z};
        const double norm = std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
        dir = norm > 0 && std::isfinite(norm) ? Vec3<double>{dir.x / norm, dir.y / norm, dir.z / norm}
                                              : Vec3<double>{0, 0, 1};
        const Vec3<double> c = sh_colour(scene.sh.data() + g * stride, scene.sh_degree, dir);
        largest = std::max({largest, c.x, c.y, c.z});
    }
    return largest;
}

namespace {

/// The scene with every opacity scaled by `factor` (Reference).
Scene with_opacities_scaled(const Scene& scene, double factor) {
    Scene s = scene;
    for (float& o : s.opacities) o = static_cast<float>(o * factor);
    return s;
}

/// Widens r.split_low / split_high (copies of low / high) by the split's range (Reference)
/// wherever the exact blend stopped.
void widen_for_split(Reference& r, const Scene& scene, const Camera& camera) {
    CpuRenderer<double> renderer;
    PartialImage partial;
    renderer.render_partial(scene, camera, options_for(Culling::exact, Mode::plain), partial);
    // Margins for SH evaluated in another precision or along a slightly different direction.
    const double c_max = largest_colour(scene, camera) * (1 + 1e-3);
    for (std::size_t p = 0; p < partial.stopped.size(); ++p) {
        if (!partial.stopped[p]) continue;
        const double t_stop = partial.transmittance[p];
        for (std::size_t ch = 0; ch < 3; ++ch) {
            const std::size_t i = 3 * p + ch;
            const double value = r.exact.image.rgb[i], bg = kBackground[ch];
            r.split_low.rgb[i] = std::min(r.split_low.rgb[i], quantize_8bit(value - t_stop * bg));
            r.split_high.rgb[i] =
                std::max(r.split_high.rgb[i], quantize_8bit(value + t_stop * std::max(0.0, c_max - bg)));
        }
    }
}

}  // namespace

std::vector<Reference> reference_frames(const StressCase& c) {
    const Scene fainter = with_opacities_scaled(c.scene, 1 - kConditioningOpacity);
    const Scene denser = with_opacities_scaled(c.scene, 1 + kConditioningOpacity);
    std::vector<Reference> out;
    for (const Camera& cam : c.path) {
        Reference r{reference_frame(c.scene, cam), {}, {}, {}, {}};
        r.low = r.high = r.exact.rgb8;
        for (const Scene* probe : {&fainter, &denser}) {
            const ImageRGB8 moved = reference_frame(*probe, cam).rgb8;
            for (std::size_t i = 0; i < moved.rgb.size(); ++i) {
                r.low.rgb[i] = std::min(r.low.rgb[i], moved.rgb[i]);
                r.high.rgb[i] = std::max(r.high.rgb[i], moved.rgb[i]);
            }
        }
        r.split_low = r.low;
        r.split_high = r.high;
        widen_for_split(r, c.scene, cam);
        out.push_back(std::move(r));
    }
    return out;
}

Measured measure(const Backend& backend, const std::vector<Frame>& frames, const std::vector<Reference>& reference,
                 bool split) {
    Measured m;
    m.rgb8_checked = backend.writes_rgb8();
    for (std::size_t k = 0; k < frames.size(); ++k) {
        m.add(frames[k], reference[k], split);
        if (!m.rgb8_checked) continue;
        const ImageRGB8 q = to_rgb8(frames[k].image);
        for (std::size_t i = 0; i < q.rgb.size() && i < frames[k].rgb8.rgb.size(); ++i)
            m.rgb8_mismatch += q.rgb[i] != frames[k].rgb8.rgb[i];
        m.rgb8_mismatch += q.rgb.size() != frames[k].rgb8.rgb.size();
    }
    return m;
}

Classes check_case(const Backend& backend, const StressCase& c, const std::string& note, bool small_image) {
    const std::vector<Reference> reference = reference_frames(c);
    std::size_t reference_nonfinite = 0;
    for (const Reference& r : reference) reference_nonfinite += count_nonfinite(r.exact.image);
    EXPECT_EQ(reference_nonfinite, 0u) << c.name << ": the double reference wrote non-finite values " << note;
    const int width = c.path[0].intrinsics.width, height = c.path[0].intrinsics.height;
    Classes classes;
    for (const Config& cfg : backend.configs()) {
        const std::vector<Frame> frames = backend.render(c, cfg);
        const Measured m = measure(backend, frames, reference, cfg.mode == Mode::split);
        classes[backend.class_label(cfg)].merge(m);
        const std::string what = c.name + ", " + backend.config_name(cfg) + ": " + describe(m) + " " + note;
        expect_within(m, backend.bound_for(c.family, cfg), small_image, what);
        if (m.rgb8_checked) {
            EXPECT_EQ(m.rgb8_mismatch, 0u) << what;
        }
        for (const Frame& f : frames) {
            EXPECT_EQ(f.image.width, width) << what;
            EXPECT_EQ(f.image.rgb.size(), 3u * static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
                << what;
        }
    }
    return classes;
}

void run_family(const Backend& backend, const FamilyGenerator& family) {
    const std::uint64_t seed = test::fresh_seed(backend.suite() + " " + family.what);
    const StressCase c = family.make(seed);
    report(backend.suite(), c.name, check_case(backend, c, seed_note(seed), false));
}

// --- Property tests -------------------------------------------------------------------

std::vector<LabelledCase> mixture_cases(std::uint64_t seed) {
    std::vector<LabelledCase> out;
    for (int k = 0; k < kMixtureSeeds; ++k) {
        const bool hdr = k % 3 == 2;
        out.push_back({mixture(seed + 1000003ull * static_cast<std::uint64_t>(k), 150, hdr),
                       seed_note(seed) + " mixture " + std::to_string(k), hdr ? "hdr mixtures" : "mixtures"});
    }
    return out;
}

std::vector<LabelledCase> field_of_view_cases(std::uint64_t seed) {
    std::vector<LabelledCase> out;
    for (double fov : {5.0, 10.0, 30.0, 60.0, 90.0, 120.0, 150.0})
        out.push_back({field_of_view(seed + static_cast<std::uint64_t>(fov), fov),
                       seed_note(seed) + " fov " + std::to_string(fov), "fov 5..150"});
    return out;
}

std::vector<LabelledCase> resolution_cases(std::uint64_t seed) {
    std::vector<LabelledCase> out;
    for (auto [w, h] :
         {std::pair{1, 1}, std::pair{1, 2}, std::pair{2, 1}, std::pair{1, 37}, std::pair{45, 1}, std::pair{15, 17},
          std::pair{16, 16}, std::pair{17, 17}, std::pair{255, 3}, std::pair{3, 129}}) {
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

void run_cases(const Backend& backend, const std::string& what, std::vector<LabelledCase> (*cases)(std::uint64_t)) {
    const std::uint64_t seed = test::fresh_seed(backend.suite() + " " + what);
    std::vector<std::pair<std::string, Classes>> groups;
    for (const LabelledCase& lc : cases(seed)) {
        auto group = std::find_if(groups.begin(), groups.end(), [&](const auto& g) { return g.first == lc.group; });
        if (group == groups.end()) group = groups.emplace(groups.end(), lc.group, Classes{});
        for (const auto& [name, m] : check_case(backend, lc.c, lc.note, lc.small_image)) group->second[name].merge(m);
    }
    for (const auto& [group, worst] : groups) report(backend.suite(), group, worst);
}

void measure_bounds(const Backend& backend) {
    const char* env = std::getenv("CATGS_STRESS_SEEDS");
    const int seeds = env ? std::atoi(env) : 20;
    const std::uint64_t base = test::fresh_seed(backend.suite() + " measure");
    Classes worst;
    for (int s = 0; s < seeds; ++s) {
        const std::uint64_t seed = base + static_cast<std::uint64_t>(s) * 7919;
        std::vector<StressCase> cases = all_families(seed);
        for (double fov : {5.0, 20.0, 90.0, 150.0})
            cases.push_back(field_of_view(seed + static_cast<std::uint64_t>(fov), fov));
        for (const StressCase& c : cases) {
            const std::vector<Reference> reference = reference_frames(c);
            const std::string family = family_name(c.family);
            for (const Config& cfg : backend.configs()) {
                Measured m = measure(backend, backend.render(c, cfg), reference, cfg.mode == Mode::split);
                for (const Reference& r : reference) m.nonfinite += count_nonfinite(r.exact.image);
                worst[family + " " + backend.class_label(cfg)].merge(m);
                worst[family + " / " + backend.config_name(cfg)].merge(m);
            }
        }
    }
    for (const auto& [name, m] : worst) std::cout << "[measure] " << name << ": " << describe(m) << std::endl;
}

}  // namespace catgs::test::stress
