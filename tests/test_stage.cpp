// The stage list is the one vocabulary of stats, JSON and docs: its order is the order a
// frame runs, and every name is distinct (a JSON key per stage).
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "catgs/render_options.hpp"
#include "catgs/stage.hpp"

namespace catgs {
namespace {

TEST(Stage, ListIsTheEnumInOrderWithDistinctNames) {
    std::set<std::string> names;
    for (std::size_t i = 0; i < kStageCount; ++i) {
        EXPECT_EQ(static_cast<std::size_t>(kStages[i]), i);
        const std::string name(stage_name(kStages[i]));
        EXPECT_NE(name, "unknown");
        EXPECT_TRUE(names.insert(name).second) << name;
    }
    EXPECT_EQ(std::string(stage_name(Stage::keys)), "keys");
    EXPECT_EQ(std::string(stage_name(Stage::copy_out)), "copy_out");
    EXPECT_EQ(kStages.back(), Stage::encode);
}

TEST(Stage, TimesIndexByStageAndSum) {
    StageTimes t;
    t[Stage::sort] = 1.5;
    t[Stage::rasterize] = 2.25;
    EXPECT_EQ(t.ms[static_cast<std::size_t>(Stage::sort)], 1.5);
    EXPECT_EQ(t[Stage::preprocess], 0.0);
    EXPECT_DOUBLE_EQ(t.sum(), 3.75);
    FrameStats stats;
    EXPECT_EQ(stats.stage_ms.sum(), 0.0);
}

}  // namespace
}  // namespace catgs
