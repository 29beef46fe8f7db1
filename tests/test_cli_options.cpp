// The tools' shared pipeline flags (renderer/tools/cli_options.hpp) as --help shows them.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <tuple>

#include "catgs/common/command_line.hpp"
#include "catgs/error.hpp"
#include "catgs/parallel.hpp"
#include "catgs/render_options.hpp"
#include "cli_options.hpp"
#include "scene_io_fixtures.hpp"

namespace {

/// --help shows the order-reuse default as a person reads it, in degrees and radians, while
/// the value parsed when the flag is not given stays the one it always was.
TEST(CliOptions, ReuseOrderDefaultReadsAsAPersonWritesIt) {
    CLI::App app{"test"};
    catgs::cli::PipelineFlags flags;
    catgs::cli::add_pipeline_flags(app, flags);
    const std::string help = app.help();
    EXPECT_NE(help.find("--reuse-order-max-deg TEXT=0.0000573 (1e-6 rad)"), std::string::npos) << help;
    EXPECT_EQ(help.find("5.72958e-05"), std::string::npos) << help;

    app.parse(std::vector<std::string>{});
    EXPECT_EQ(flags.reuse_order_max_deg, catgs::cli::PipelineFlags::angle_name(catgs::kDefaultReuseOrderMaxAngle));
    catgs::RenderOptions options;
    catgs::cli::apply_pipeline_flags(flags, options);
    EXPECT_DOUBLE_EQ(options.catgs.reuse_order_max_angle,
                     *catgs::parse_degrees(flags.reuse_order_max_deg) * catgs::kPi / 180.0);
    EXPECT_NEAR(options.catgs.reuse_order_max_angle, catgs::kDefaultReuseOrderMaxAngle, 1e-12);
    // Benchmark tables and logs describe it the same way.
    const std::string described = catgs::cli::describe_pipeline(options);
    EXPECT_NE(described.find("depth order reused within 0.0000573 deg (1e-6 rad)"), std::string::npos) << described;

    // Other values show the same way; "any" as itself.
    for (const auto& [value, shown] : {std::pair{"180", "TEXT=180 (3.14 rad)"},
                                       std::pair{"0.05", "TEXT=0.05 (0.000873 rad)"}, std::pair{"any", "TEXT=any"}}) {
        CLI::App other{"test"};
        catgs::cli::PipelineFlags f;
        f.reuse_order_max_deg = value;
        catgs::cli::add_pipeline_flags(other, f);
        EXPECT_NE(other.help().find(std::string("--reuse-order-max-deg ") + shown), std::string::npos) << other.help();
    }
}

}  // namespace

namespace {

/// A --sweep entry takes the pipeline flags only; a run-wide flag in it is named as written,
/// with what an entry takes instead (CLI11 alone listed it backwards: "double --precision").
TEST(CliOptions, SweepEntryNamesAFlagItDoesNotTake) {
    const auto configs = catgs::cli::parse_sweep("plain: --cache off --split off; w4: --window 4");
    ASSERT_EQ(configs.size(), 2u);
    EXPECT_EQ(configs[0].name, "plain");
    EXPECT_EQ(configs[1].options.catgs.window, 4);
    try {
        catgs::cli::parse_sweep("plain: --cache off; double: --precision double --split off");
        ADD_FAILURE() << "--precision in a sweep entry must be refused";
    } catch (const catgs::Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("--sweep entry 'double': '--precision double' is not a pipeline flag"), std::string::npos)
            << what;
        EXPECT_NE(what.find("an entry takes --"), std::string::npos) << what;
        EXPECT_NE(what.find(", --split,"), std::string::npos) << what;
        EXPECT_EQ(what.find("--help"), std::string::npos) << what;
        EXPECT_NE(what.find("go before --sweep"), std::string::npos) << what;
    }
}

/// --spz-axes takes rdf or rub in any case (without the flag the caller's value, rdf in the
/// tools, stays), and names the flag and the words it takes when given anything else.
TEST(CliOptions, SpzAxesTakesRdfOrRub) {
    for (const auto& [args, start, expected] :
         {std::tuple{"", catgs::SpzAxes::rub, catgs::SpzAxes::rub},
          std::tuple{"--spz-axes rub", catgs::SpzAxes::rdf, catgs::SpzAxes::rub},
          std::tuple{"--spz-axes RUB", catgs::SpzAxes::rdf, catgs::SpzAxes::rub},
          std::tuple{"--spz-axes rdf", catgs::SpzAxes::rub, catgs::SpzAxes::rdf}}) {
        CLI::App app{"test"};
        catgs::cli::SceneFlags flags{"builtin:city"};
        flags.spz_axes = start;
        catgs::cli::add_scene_flags(app, flags);
        app.parse(args, false);
        EXPECT_EQ(flags.spz_axes, expected) << "'" << args << "'";
    }
    CLI::App app{"test"};
    catgs::cli::SceneFlags flags{"builtin:city"};
    catgs::cli::add_scene_flags(app, flags);
    try {
        app.parse("--spz-axes luf", false);
        FAIL() << "luf accepted";
    } catch (const CLI::ParseError& e) {
        EXPECT_NE(std::string(e.what()).find("--spz-axes: luf not in {rdf,rub}"), std::string::npos) << e.what();
    }
}

/// catgs-render and catgs-bench load a scene with invalid records alike: refused, naming the
/// record, unless --drop-invalid, which drops it and says so on stderr (a benchmark must not
/// time fewer Gaussians than the file holds without telling).
TEST(CliOptions, DropInvalidDropsAndTellsOrTheLoadIsRefused) {
    using namespace catgs::scene_io_test;
    Ply ply = graphdeco_ply(5, 0);
    ply.rows[3]["scale_1"] = std::numeric_limits<double>::quiet_NaN();
    const std::string path = tmp_path("nan.ply");
    write_file(path, ply.bytes());

    CLI::App strict_app{"test"};
    catgs::cli::SceneFlags strict{"builtin:city"};
    catgs::cli::add_scene_flags(strict_app, strict);
    strict_app.parse("--scene " + path, false);
    EXPECT_FALSE(strict.drop_invalid);
    const std::string message = catgs::test::error_of([&] { catgs::cli::load_scene(strict, true); });
    EXPECT_NE(message.find("record 3, property 'scale_1'"), std::string::npos) << message;

    CLI::App app{"test"};
    catgs::cli::SceneFlags flags{"builtin:city"};
    catgs::cli::add_scene_flags(app, flags);
    app.parse("--scene " + path + " --drop-invalid", false);
    ASSERT_TRUE(flags.drop_invalid);
    ::testing::internal::CaptureStderr();
    const catgs::Scene scene = catgs::cli::load_scene(flags, false);
    const std::string told = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(scene.count(), 4u);
    EXPECT_NE(told.find("dropped 1 invalid and 0 transparent (opacity < 1/255) Gaussians of 5\n"), std::string::npos)
        << told;

    ::testing::internal::CaptureStderr();
    EXPECT_EQ(catgs::cli::load_scene(flags, true).count(), 4u);
    EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
}

/// --width, --height and --fov are refused as they are parsed, before a scene loads, with the
/// bound in the message; values inside the bounds pass unchanged.
TEST(CliOptions, ImageSideAndFieldOfViewAreCheckedWhenParsed) {
    const auto parse = [](const std::string& args, int& width, double& fov) {
        CLI::App app{"test"};
        app.add_option("--width", width)->check(catgs::image_side());
        app.add_option("--fov", fov)->check(catgs::horizontal_fov());
        app.parse(args, false);
    };
    int width = 1;
    double fov = 1;
    parse("--width 16384 --fov 179.9", width, fov);
    EXPECT_EQ(width, 16384);
    EXPECT_DOUBLE_EQ(fov, 179.9);
    parse("--fov 0.001", width, fov);
    EXPECT_DOUBLE_EQ(fov, 0.001);
    for (const auto& [args, message] :
         {std::pair{"--width 0", "--width: Value 0 not in range 1 to 16384"},
          std::pair{"--width 16385", "--width: Value 16385 not in range 1 to 16384"},
          std::pair{"--fov 180", "--fov: expected a horizontal field of view in degrees in [0.001, 179.9], not 180"},
          std::pair{"--fov 179.95", "in [0.001, 179.9], not 179.95"}, std::pair{"--fov 0", "in [0.001, 179.9], not 0"},
          std::pair{"--fov 0.0005", "in [0.001, 179.9], not 0.0005"},
          std::pair{"--fov -5", "in [0.001, 179.9], not -5"}, std::pair{"--fov nan", "in [0.001, 179.9], not nan"}}) {
        try {
            parse(args, width, fov);
            FAIL() << args << " accepted";
        } catch (const CLI::ParseError& e) {
            EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << args << ": " << e.what();
        }
    }
}

// --quality is refused outside 1..100 while parsing, with the range in the message.
TEST(CliOptions, JpegQualityIsCheckedWhenParsed) {
    const auto parse = [](const std::string& args, int& quality) {
        CLI::App app{"test"};
        app.add_option("--quality", quality)->check(catgs::jpeg_quality());
        app.parse(args, false);
    };
    int quality = 0;
    parse("--quality 100", quality);
    EXPECT_EQ(quality, 100);
    parse("--quality 1", quality);
    EXPECT_EQ(quality, 1);
    for (const char* args : {"--quality 0", "--quality 101", "--quality -5"}) {
        try {
            parse(args, quality);
            FAIL() << args << " accepted";
        } catch (const CLI::ParseError& e) {
            EXPECT_NE(std::string(e.what()).find("not in range 1 to 100"), std::string::npos)
                << args << ": " << e.what();
        }
    }
}

// Thread counts from 0 (all cores) to kMaxThreads: a negative count or a typo such as 100000
// is refused while parsing, before any thread starts.
TEST(CliOptions, ThreadCountsAreCheckedWhenParsed) {
    const auto parse = [](const std::string& args) {
        int threads = -7;
        CLI::App app{"test"};
        app.add_option("--threads", threads)->check(catgs::thread_count());
        app.parse(args, false);
        return threads;
    };
    EXPECT_EQ(parse("--threads 0"), 0);
    EXPECT_EQ(parse("--threads 1024"), catgs::kMaxThreads);
    for (const auto& [args, message] : {std::pair{"--threads -1", "--threads: Value -1 not in range 0 to 1024"},
                                        std::pair{"--threads 1025", "--threads: Value 1025 not in range 0 to 1024"},
                                        std::pair{"--threads 100000", "not in range 0 to 1024"}}) {
        try {
            parse(args);
            FAIL() << args << " accepted";
        } catch (const CLI::ParseError& e) {
            EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << args << ": " << e.what();
        }
    }
}

// bounded_number refuses NaN, which CLI::Range lets through (NaN compares false both ways).
TEST(CliOptions, BoundedNumbersRefuseNanAndNameTheUnit) {
    const auto parse = [](const std::string& args) {
        double rate = -1;
        CLI::App app{"test"};
        app.add_option("--rate", rate)->check(catgs::bounded_number(0, 1000, "poses per second"));
        app.parse(args, false);
        return rate;
    };
    EXPECT_EQ(parse("--rate 0"), 0);
    EXPECT_EQ(parse("--rate 1000"), 1000);
    for (const char* value : {"nan", "-0.5", "1000.5", "inf", "abc"}) {
        try {
            parse(std::string("--rate ") + value);
            FAIL() << value << " accepted";
        } catch (const CLI::ParseError& e) {
            EXPECT_EQ(std::string(e.what()),
                      std::string("--rate: expected poses per second in [0, 1000], not ") + value);
        }
    }
}

// --occlusion-cut: off in the defaults the tools start from (it does not pay yet), on when
// asked, and any other word is refused naming the flag and the words it takes.
TEST(CliOptions, OcclusionCutTakesOnOrOff) {
    const auto apply = [](const std::string& args) {
        CLI::App app{"test"};
        catgs::cli::PipelineFlags flags;
        catgs::cli::add_pipeline_flags(app, flags);
        app.parse(args, false);
        catgs::RenderOptions options;
        catgs::cli::apply_pipeline_flags(flags, options);
        return options;
    };
    EXPECT_FALSE(apply("").catgs.occlusion_cut);
    EXPECT_EQ(catgs::cli::describe_pipeline(apply("")).find("occlusion cut"), std::string::npos);
    EXPECT_TRUE(apply("--occlusion-cut on").catgs.occlusion_cut);
    EXPECT_NE(catgs::cli::describe_pipeline(apply("--occlusion-cut on")).find("occlusion cut"), std::string::npos);
    EXPECT_FALSE(apply("--occlusion-cut off").catgs.occlusion_cut);
    try {
        apply("--occlusion-cut yes");
        FAIL() << "yes accepted";
    } catch (const catgs::Error& e) {
        EXPECT_EQ(std::string(e.what()), "--occlusion-cut 'yes': expected on or off");
    }
}

}  // namespace
