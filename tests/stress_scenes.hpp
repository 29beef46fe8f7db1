// Adversarial scenes for the numerical stress suite (tests/stress_suite.cpp runs the families
// on every backend; tests/test_stress*.cpp and tests/gpu/test_cuda_stress.cpp hold each
// backend's own tests). Each generator builds a catgs::Scene directly, with ACTIVATED values
// (linear scales, (w, x, y, z) quaternions, opacity in (0, 1]), because the values a loader
// would reject (NaN, zero quaternions) must still be survivable when a Scene holds them.
//
// Every generator takes a seed, so a failure replays with CATGS_TEST_SEED (test_util.hpp),
// and returns a StressCase: the scene, a short camera path (frame 0 is the single-frame
// camera; all six frames are rendered for the speculative cache) and its family, which
// selects the error bounds in the tests. The definitions are in stress_scenes.cpp (the
// mixtures: stress_mixture_scenes.cpp; the targeted scenes: stress_targeted_scenes.cpp).
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "catgs/camera.hpp"
#include "catgs/scene.hpp"

namespace catgs::test::stress {

/// The case families of the issue. Each has its own error bounds per backend.
enum class Family {
    tiny_scales,    ///< scales 1e-12 .. 1e-45 and 0 on some or all axes
    huge_scales,    ///< scales 1e3 .. 1e6, camera inside some of them
    quaternions,    ///< zero, NaN, inf, denormal and non-normalised quaternions
    opacities,      ///< logits +-100 (1.0f and 3.7e-44), exactly 1.0f, 1/255 +- 1 ulp, 0
    huge_sh,        ///< SH coefficients of magnitude 1e30 (both signs, every degree)
    extreme_sh,     ///< SH coefficients 1e38 (near float max), +inf, -inf, NaN
    near_plane,     ///< at the camera centre, 0.2 +- (1e-5 .. 1e-2), behind the camera
    image_border,   ///< means exactly on the image border and on tile boundaries
    far_away,       ///< 10^7 m from the camera, scales up to 1e5
    utm,            ///< scene origin and camera at 10^6 .. 10^7 m
    camera_inside,  ///< the camera inside large Gaussians whose mean is in front of it
    degenerate,     ///< 2D covariances that are rank one before the blur: 1e-20 x 1e-20 x 1,
                    ///< needles seen end-on, discs seen edge-on
    invalid,        ///< NaN / inf positions, scales, opacities
    ties,           ///< thousands of Gaussians at exactly the same depth
    field_of_view,  ///< a mixture seen at 5 .. 150 degrees
    mixture,        ///< random draws from every family above in one scene, SH 1e30 excluded
    hdr_mixture,    ///< the mixture with SH 1e30 colours included
};

const char* family_name(Family f);

inline constexpr float kInf = std::numeric_limits<float>::infinity();
inline constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// The activated opacity a loader computes from a logit, in float as it stores it:
/// sigmoid(100) rounds to exactly 1.0f, sigmoid(-100) to the denormal 3.7e-44f.
float activated_opacity(double logit);

/// One Gaussian, activated. `sh` (if not empty) holds every coefficient of the scene's
/// degree; otherwise DC = dc and every higher coefficient is `rest` with alternating sign.
struct Gaussian {
    std::array<float, 3> position{0, 0, 5};
    std::array<float, 3> scale{0.1f, 0.1f, 0.1f};
    std::array<float, 4> rotation{1, 0, 0, 0};
    float opacity = 0.8f;
    std::array<float, 3> dc{0, 0, 0};
    float rest = 0;
    std::vector<float> sh;
};

/// Appends a Gaussian to `s` (whose sh_degree is already set).
void add(Scene& s, const Gaussian& g);

/// Random draws for the generators.
class Draw {
public:
    explicit Draw(std::uint64_t seed) : rng_(seed) {}
    std::mt19937_64& rng() { return rng_; }
    double uniform(double lo = 0, double hi = 1) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }
    double log_uniform(double lo, double hi);
    int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }  // [lo, hi]
    bool chance(double p) { return uniform() < p; }
    template <typename V>
    const typename V::value_type& pick(const V& values) {
        return values[static_cast<std::size_t>(integer(0, static_cast<int>(values.size()) - 1))];
    }
    std::array<float, 4> unit_quaternion();
    std::array<float, 3> colour();
    /// An ordinary Gaussian in the view frustum of a camera at the origin looking down +z
    /// (fov up to ~150 degrees): the background the adversarial ones interact with.
    Gaussian ordinary(double depth_min = 1.0, double depth_max = 12.0);

private:
    std::mt19937_64 rng_;
};

/// A quaternion (w, x, y, z) whose rotation maps the local x axis onto `dir` (unit): the long
/// axis of a needle with scale (long, thin, thin) then points along `dir`.
std::array<float, 4> quaternion_x_to(std::array<double, 3> dir);

/// A scene of the given SH degree (origin 0) with nothing in it yet.
Scene empty_scene(int sh_degree);

/// A camera path of `frames` frames at 30 fps, starting at `start`, translating by `step`
/// metres per frame along the camera's x axis and turning by `turn` radians per frame about
/// its y axis: slow enough that the speculative cache serves some frames from its lists.
std::vector<Camera> short_path(const Camera& start, double step = 0.002, double turn = 1e-4, int frames = 6);

struct StressCase {
    std::string name;
    Family family;
    Scene scene;
    std::vector<Camera> path;  ///< frame 0 is the single-frame camera
};

/// A case of `scene` (its bounds updated) on short_path() from `camera`.
StressCase make_case(std::string name, Family family, Scene scene, const Camera& camera);

/// The unit vector from the camera centre (the origin) towards `position`.
std::array<double, 3> direction_to(const std::array<float, 3>& position);

/// Default image of the family cases: small (CI), with a partial tile on each axis.
inline constexpr int kCaseWidth = 72, kCaseHeight = 40;

/// The camera of the family cases: the default image at `fov` degrees horizontally.
Camera case_camera(double fov = 60);

/// The default path without the turn. Scenes with near-plane Gaussians need it: a turning
/// camera sweeps some of them across the plane, and one that lands within float rounding of
/// it is drawn by one precision and culled by the other (StressNearPlane covers that boundary
/// on its own). Scenes of equal depths need it to keep the depths equal on cached frames.
std::vector<Camera> sideways_path(const Camera& start);

// --- Families -------------------------------------------------------------------------

/// Scales 1e-12, 1e-20, 1e-30, 1e-45 (denormal) and 0 on one, two or three axes: the 3D
/// covariance underflows, the 2D covariance is the 0.3 blur (a one-pixel dot) or a line.
StressCase tiny_scales(std::uint64_t seed);
/// Scales 1e3 .. 1e6 (isotropic and mixed with ordinary axes), in front of the camera,
/// some containing the camera: the 2D covariance reaches 1e19 px^2 (1e38 for the
/// determinant, float's limit).
StressCase huge_scales(std::uint64_t seed);
/// Zero, NaN, inf, denormal and non-normalised quaternions. Rendering uses quat_to_matrix
/// as it is (no normalisation): a zero quaternion is the identity, a quaternion k q gives
/// I + k^2 (R(q) - I), not a rotation, and NaN/inf ones make the covariance NaN (culled).
StressCase quaternions(std::uint64_t seed);
/// Opacities from logits +-100 (1.0f and the denormal 3.7e-44f), exactly 1.0f, the largest
/// float below 1, 1/255 and its float neighbours, and 0: alpha hits the 0.99 cap, the 1/255
/// skip and the 1e-4 transmittance stop exactly.
StressCase opacities(std::uint64_t seed);
/// SH coefficients of magnitude 1e30 in every degree and both signs, mixed with ordinary
/// Gaussians: colours 1e30 saturate every pixel they reach with alpha >= 1/255.
StressCase huge_sh(std::uint64_t seed);
/// SH coefficients 1e38 (near float max: a degree-3 sum can overflow float), +inf, -inf
/// and NaN.
StressCase extreme_sh(std::uint64_t seed);
/// Gaussians at the camera centre, just in front of and just behind the near plane 0.2
/// (relative offsets 1e-5 .. 1e-2, so that float and double agree on which side they are;
/// StressNearPlane covers the ones within an ulp separately) and behind the camera.
StressCase near_plane(std::uint64_t seed);
/// Means exactly on the image border (x = 0, x = width, y = 0, y = height: pixel centres
/// are at +0.5) and on tile boundaries, small and large.
StressCase image_border(std::uint64_t seed);
/// Gaussians 10^7 m away (on screen with scales 1e4 .. 1e5, far outside the frustum, and
/// behind), in front of an ordinary scene; and some at finite but absurd lateral offsets
/// (1e20 m at a depth of metres), whose means lie 1e21 px off-screen so that dx^2 overflows
/// float in the blend.
StressCase far_away(std::uint64_t seed);
/// A scene whose origin is at UTM-sized coordinates (10^6 .. 10^7 m), the camera there too
/// and rotated (look_at): positions are float offsets from the double origin.
StressCase utm(std::uint64_t seed);
/// The camera inside large Gaussians (scales 1 .. 1e3, mean in front of the near plane,
/// the camera within one sigma), with ordinary ones behind: alpha is nearly uniform over
/// the screen.
StressCase camera_inside(std::uint64_t seed);
/// Rank-one-before-the-blur 2D covariances: scales 1e-20 x 1e-20 x 1 (the 3D determinant
/// underflows in float), needles (thin 1e-6 .. 1e-3, long 0.1 .. 1e3) seen end-on along the
/// ray through their mean, flat discs seen edge-on.
StressCase degenerate(std::uint64_t seed);
/// Values a loader rejects: NaN / inf positions, NaN / inf scales, NaN opacity, NaN SH.
/// A non-finite position, scale or opacity must cull the Gaussian (draw nothing of it) in
/// every mode; a NaN SH colour is clamped to 0: the Gaussian is drawn black.
StressCase invalid(std::uint64_t seed);
/// Ties: 2000 Gaussians at depth 5 and 1000 at depth 8 (exactly, for the camera at the
/// origin: the view depth of each is the same float), in index order of nothing in
/// particular: equal depths must be ordered by index, deterministically.
StressCase ties(std::uint64_t seed);

/// `count` adversarial Gaussians in one scene, every kind above at random; with
/// `huge_colours`, SH 1e30 among them.
StressCase mixture(std::uint64_t seed, int count = 150, bool huge_colours = false);
/// The mixture seen with a horizontal field of view of `fov` degrees (5 .. 150).
StressCase field_of_view(std::uint64_t seed, double fov);

/// One family of the suite: the generator, how its test is named (StressFamilies.Family/
/// <backend>_<test_name>) and how its seed is labelled ("<suite> <what>").
struct FamilyGenerator {
    const char* test_name;
    const char* what;
    StressCase (*make)(std::uint64_t seed);
};

/// The families that run as tests of their own, tiny_scales .. ties in the enum's order (the
/// mixtures and fields of view run as property tests over several cases).
const std::vector<FamilyGenerator>& family_generators();

/// Every family once: family_generators(), then the mixture and the hdr mixture (field of
/// view at 60 degrees is the mixture).
std::vector<StressCase> all_families(std::uint64_t seed);

/// `count` Gaussians at exactly the same view depth `z` (ties), overlapping on screen.
Scene equal_depth(std::uint64_t seed, int count, float z = 5.0f);

// --- Single Gaussians ------------------------------------------------------------------

/// A scene of one Gaussian at `p`; with `sh_degree` > 0 every SH coefficient is `sh_value`.
Scene one_gaussian(std::array<float, 3> p, std::array<float, 3> s, std::array<float, 4> q, float opacity,
                   std::array<float, 3> dc, int sh_degree = 0, float sh_value = 0);

// --- Cache envelope ------------------------------------------------------------------
// Cases for the speculative cache's envelope: each backend renders the path with the cache
// and without, and the cached frames must match (the StressBugs of test_stress_analytic.cpp).
// No family bound applies; `family` names the closest family.

/// 30 ordinary Gaussians 3 .. 12 m away and, in a 4 x 3 grid 2 .. 3 m away, alternately
/// needles pointing at the camera and discs seen edge-on (one-pixel footprints that open up
/// as the line of sight turns), on a 160 x 96 camera moving 5 mm a frame sideways.
StressCase needles_and_discs_end_on(std::uint64_t seed);
/// 40 ordinary Gaussians 8 .. 12 m away and a small bright one at 0.3 m depth whose mean is
/// 6 px right of a 72 x 40 image; the camera moves 5 cm a frame to the right, which brings the
/// near one into the image by 10 px a frame while the far ones move less than a pixel.
StressCase near_gaussian_outside_the_image(std::uint64_t seed);

// --- Large images ---------------------------------------------------------------------

/// `count` Gaussians with bounded footprints (sigma 0.3 .. 40 px, so a few tiles each) for a
/// large image: at the corners, on the border, on tile boundaries, at the centre and at
/// random, some opaque (1.0), some with a 1e-12 axis, some with zero scales (the blur).
Scene local_gaussians(std::uint64_t seed, const Camera& cam, int count);

/// Pixel boxes {x0, y0, x1, y1} (half-open) around the footprint of every Gaussian visible to
/// `cam` (the box of q <= its opacity level, grown by `margin`), merged where they overlap,
/// so that every Gaussian reaching a box has its mean inside it.
std::vector<std::array<int, 4>> footprint_boxes(const Scene& scene, const Camera& cam, int margin = 4);

/// The camera that renders exactly the pixels `box` of `cam`: same focal lengths, principal
/// point shifted. Projection is identical for every Gaussian whose mean is inside the box (the
/// Jacobian clamp, principal-point aware, only differs beyond it).
Camera crop_camera(const Camera& cam, const std::array<int, 4>& box);

}  // namespace catgs::test::stress
