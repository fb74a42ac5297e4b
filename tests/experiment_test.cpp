// SPDX-License-Identifier: Apache-2.0
// `texcache experiment <name> --quick` end to end: every experiment runs at test size and writes
// its CSV (finite numbers, at least the expected rows), its PNG plots and its markdown summary;
// an unknown name is a clear error listing the valid ones.
#include <gtest/gtest.h>

#include <ostream>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

#include "cli_run.h"

namespace {

namespace fs = std::filesystem;

using texcache::test::CliRun;
using texcache::test::Texcache;

// Rows of a CSV (header excluded); fails the test on a non-finite number.
int CheckCsv(const fs::path& path) {
    std::ifstream f(path);
    EXPECT_TRUE(f.good()) << path;
    std::string line;
    std::getline(f, line);
    int rows = 0;
    while (std::getline(f, line)) {
        ++rows;
        std::stringstream ss(line);
        std::string cell;
        while (std::getline(ss, cell, ',')) {
            char* end = nullptr;
            const double v = std::strtod(cell.c_str(), &end);
            if (end != cell.c_str() && *end == '\0') {
                EXPECT_TRUE(std::isfinite(v)) << path << ": " << line;
            }
            EXPECT_NE(cell, "nan") << path << ": " << line;
        }
    }
    return rows;
}

struct Expected {
    std::string name, csv;
    int minRows;
    std::vector<std::string> pngs;
};
// GoogleTest would print the parameter as a byte dump (heap pointers included), which CTest then
// takes into the test's name: print the experiment's name.
void PrintTo(const Expected& e, std::ostream* os) {
    *os << e.name;
}

class Experiment : public ::testing::TestWithParam<Expected> {};

TEST_P(Experiment, QuickRunWritesCsvPlotsAndSummary) {
    const Expected& e = GetParam();
    const fs::path out = fs::path(::testing::TempDir()) / ("texcache_exp_" + e.name);
    fs::remove_all(out);
    const CliRun r = Texcache("experiment " + e.name + " --quick --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_GE(CheckCsv(out / (e.csv + ".csv")), e.minRows);
    for (const std::string& png : e.pngs) {
        EXPECT_TRUE(fs::exists(out / png)) << png << "\n" << r.out;
        EXPECT_GT(fs::file_size(out / png), 1000u) << png;
    }
    std::ifstream md(out / (e.csv + ".md"));
    std::stringstream text;
    text << md.rdbuf();
    EXPECT_NE(text.str().find("Paper"), std::string::npos) << "the summary quotes the paper";
    EXPECT_NE(text.str().find("Quick mode"), std::string::npos);
    if (e.name == "speed-vs-error") {
        // The experiment's goals per case, and for the path cases the bound the per-hit terms put
        // on any method that caches the diffuse term.
        EXPECT_NE(text.str().find("## The goals"), std::string::npos);
        EXPECT_NE(text.str().find("| car-indirect | ts-normal | "), std::string::npos);
        EXPECT_NE(text.str().find("- car-indirect: "), std::string::npos);
        EXPECT_NE(text.str().find("the per-hit terms alone give relMSE"), std::string::npos);
    }
}

INSTANTIATE_TEST_SUITE_P(
    All, Experiment,
    ::testing::Values(
        Expected{"speed-vs-error",
                 "speed_vs_error",
                 5 * 5 * 2 + 2 * 4 * 2 + 2 * 2,
                 {"speed_vs_error_car-ao_seconds.png", "speed_vs_error_chess-softshadow_rays.png",
                  "sve_car-ao_ts-regression.png"}},
        Expected{"cache-size", "cache_size", 15, {"cache_size.png"}},
        Expected{"stereo-store", "stereo_store", 2 * 3, {}},
        Expected{"filter-size",
                 "filter_size",
                 2 * 11,
                 {"filter_size.png", "filter_size_all21.png", "filter_size_visible21.png"}},
        Expected{"threads", "threads", 6, {"threads.png"}},
        Expected{"lod-bias", "lod_bias", 4, {"lod_bias.png", "lod_bias_3.png"}},
        Expected{"cpis", "cpis", 7 + 4 + 7, {"cpis_seconds.png", "cpis_rays.png", "cpis_cpis.png"}},
        Expected{"blur",
                 "blur",
                 2 * (3 + 2 * 2),
                 {"blur_blur_motion.png", "blur_blur_defocus_blurred.png",
                  "blur_blur_motion_focus.png"}},
        Expected{"equal-time",
                 "equal_time",
                 6 * 3 * 2,
                 {"equal_time_pieces_forest.png", "equal_time_tent_lens_ao.png"}}),
    [](const ::testing::TestParamInfo<Expected>& i) {
        std::string n = i.param.name;
        for (char& c : n)
            if (c == '-') c = '_';
        return n;
    });

// A run of some cases keeps the other cases of an earlier run in the same directory (nothing a
// user measured is lost to a rerun of one case); a CSV it cannot read is a clear error naming the
// file and line, and is left as it was.
TEST(SpeedVsError, RunsOfSomeCasesKeepTheOthers) {
    const fs::path out = fs::path(::testing::TempDir()) / "texcache_exp_sve_merge";
    fs::remove_all(out);
    CliRun r =
        Texcache("experiment speed-vs-error --quick --only chess-softshadow --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    r = Texcache("experiment speed-vs-error --quick --only car-ao --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    // Rows of the CSV per case (its first column), after the header.
    auto rowsPerCaseOf = [](const fs::path& csv) {
        std::map<std::string, int> rows;
        std::ifstream f(csv);
        std::string line;
        std::getline(f, line);
        while (std::getline(f, line)) ++rows[line.substr(0, line.find(','))];
        return rows;
    };
    std::map<std::string, int> rowsPerCase = rowsPerCaseOf(out / "speed_vs_error.csv");
    EXPECT_EQ(rowsPerCase["chess-softshadow"], 3 * 2);  // per-hit, hits, softshadow; 2 budgets
    EXPECT_EQ(rowsPerCase["car-ao"], 7 * 2);
    std::ifstream md(out / "speed_vs_error.md");
    std::stringstream text;
    text << md.rdbuf();
    EXPECT_NE(text.str().find("- chess-softshadow: "), std::string::npos);
    EXPECT_NE(text.str().find("- car-ao: "), std::string::npos);

    // --methods reruns some methods of a case and keeps its other methods' rows; an unknown
    // method is a clear error naming the valid ones.
    r = Texcache(
        "experiment speed-vs-error --quick --only car-ao --methods ts-hits,per-hit --out " +
        out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("keeping 16 rows"), std::string::npos) << r.out;  // 6 + 5 x 2 not rerun
    rowsPerCase = rowsPerCaseOf(out / "speed_vs_error.csv");
    EXPECT_EQ(rowsPerCase["chess-softshadow"], 3 * 2);
    EXPECT_EQ(rowsPerCase["car-ao"], 7 * 2);
    r = Texcache("experiment speed-vs-error --quick --only car-ao --methods ts-nothing --out " +
                 out.string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("no method named 'ts-nothing'"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("ts-hits"), std::string::npos) << r.out;

    // A damaged CSV: the run stops before rendering and the file is kept.
    {
        std::ofstream bad(out / "speed_vs_error.csv", std::ios::app);
        bad << "car-ao,ts-none,1\n";
    }
    const auto size = fs::file_size(out / "speed_vs_error.csv");
    r = Texcache("experiment speed-vs-error --quick --only chess-ao --out " + out.string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("speed_vs_error.csv:22"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("3 values, expected 11"), std::string::npos) << r.out;
    EXPECT_EQ(fs::file_size(out / "speed_vs_error.csv"), size);
    fs::remove_all(out);
}

// The temporal experiment (not in the list above: it checks more and runs once): its plots and
// crops exist, every method and demodulation setting has a finite RMSE in [0, 10) on every frame
// of every scene, and the summary quotes the paper and decides both of the experiment's goals.
TEST(TemporalExperiment, EveryMethodHasFiniteRmseOnEveryScene) {
    const fs::path out = fs::path(::testing::TempDir()) / "texcache_exp_temporal_rmse";
    fs::remove_all(out);
    const CliRun r = Texcache("experiment temporal --quick --ablation --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    std::ifstream f(out / "temporal.csv");
    std::string line;
    std::getline(f, line);
    ASSERT_EQ(line,
              "scene,method,demodulation,frame,rmse,ssim,temporal_change,ms,cpu_ms,rmse_direct,"
              "rmse_glossy,rmse_indirect");
    std::map<std::string, int> rows;  // "scene/method/demodulation" -> frames with a finite RMSE
    int quoted = 0;
    while (std::getline(f, line)) {
        // Labels with commas (the ablation's "reliable, alpha 0.1") are quoted: with each quoted
        // value as one cell, every row has the header's 12 values.
        const std::string plain = std::regex_replace(line, std::regex("\"[^\"]*\""), "label");
        quoted += plain != line;
        std::vector<std::string> c;
        std::stringstream ss(plain);
        std::string cell;
        while (std::getline(ss, cell, ',')) c.push_back(cell);
        if (plain.back() == ',') c.push_back("");
        ASSERT_EQ(c.size(), 12u) << line;
        const double rmse = std::strtod(c[4].c_str(), nullptr);
        EXPECT_TRUE(std::isfinite(rmse) && rmse >= 0.0 && rmse < 10.0) << line;
        if (std::isfinite(rmse)) ++rows[c[0] + "/" + c[1] + "/" + c[2]];
    }
    EXPECT_GT(quoted, 0);  // --ablation wrote its labels
    for (const char* scene :
         {"anim_shadow", "anim_light", "anim_glossy", "anim_disocclusion", "anim_flythrough"})
        for (const char* method : {"spatial", "baseline", "baseline+clamp", "reliable"})
            for (const char* demod : {"off", "on"}) {
                const std::string key = std::string(scene) + "/" + method + "/" + demod;
                EXPECT_EQ(rows[key], 8) << key;
            }
    for (const char* png :
         {"temporal_rmse_anim_shadow.png", "temporal_change_anim_flythrough.png",
          "temporal_crop_anim_glossy.png", "temporal_crop_anim_disocclusion.png"}) {
        EXPECT_TRUE(fs::exists(out / png)) << png << "\n" << r.out;
        EXPECT_GT(fs::file_size(out / png), 1000u) << png;
    }
    std::ifstream md(out / "temporal.md");
    std::stringstream text;
    text << md.rdbuf();
    for (const char* needle : {"Paper", "Quick mode", "**Goal 1: ", "**Goal 2: "})
        EXPECT_NE(text.str().find(needle), std::string::npos) << needle;
    // --ablation: Reliable with one setting changed, on every scene, beside the defaults.
    std::ifstream ab(out / "temporal_ablation.md");
    std::stringstream abText;
    abText << ab.rdbuf();
    for (const char* scene :
         {"anim_shadow", "anim_light", "anim_glossy", "anim_disocclusion", "anim_flythrough"})
        for (const char* variant : {"alpha 0.1", "glossy jitter 4", "no clamping", "baseline"})
            EXPECT_NE(abText.str().find(std::string("| ") + scene + " | " +
                                        (std::string(variant) == "baseline" ? "" : "reliable, ") +
                                        variant),
                      std::string::npos)
                << scene << " " << variant << "\n"
                << abText.str();
}

// `experiment disocclusion --quick`: each way of rendering the quick mode runs (per hit, cache,
// cache with temporal accumulation, cache with cached visibility) gets a row with newly
// disoccluded pixels, finite RMSE figures in [0, 10) and a positive frame CPU time.
TEST(DisocclusionExperiment, EveryRowHasPixelsAndFiniteRmse) {
    const fs::path out = fs::path(::testing::TempDir()) / "texcache_exp_disocclusion";
    fs::remove_all(out);
    const CliRun r = Texcache("experiment disocclusion --quick --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    std::ifstream f(out / "disocclusion.md");
    std::string line;
    int rows = 0;
    while (std::getline(f, line)) {
        if (line.rfind("| per hit |", 0) != 0 && line.rfind("| cache", 0) != 0) continue;
        ++rows;
        std::vector<double> v;
        std::stringstream ss(line);
        std::string cell;
        while (std::getline(ss, cell, '|')) {
            char* end = nullptr;
            const double x = std::strtod(cell.c_str(), &end);
            if (end != cell.c_str()) v.push_back(x);
        }
        // pixels, 9 RMSE figures at k = 0..2 (image, indirect, direct), the direct RMSE of
        // frame 0, the frame CPU time (ms; "mean +- std": the mean is read)
        ASSERT_EQ(v.size(), 12u) << line;
        EXPECT_GT(v[0], 0.0) << line;
        for (size_t i = 1; i < 11; ++i)
            EXPECT_TRUE(std::isfinite(v[i]) && v[i] >= 0.0 && v[i] < 10.0) << line;
        EXPECT_GT(v[11], 0.0) << line;
    }
    EXPECT_EQ(rows, 4) << r.out;
}

// `experiment stereo --quick`: a CSV with the experiment's columns and a row per case and
// separation, the plot and the summary; at zero separation the second eye shades no new sample.
TEST(StereoExperiment, WritesCostsPerSeparation) {
    const fs::path out = fs::path(::testing::TempDir()) / "texcache_exp_stereo";
    fs::remove_all(out);
    const CliRun r = Texcache("experiment stereo --quick --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_EQ(CheckCsv(out / "stereo.csv"), 8);  // 2 scenes x 2 reuse modes x 2 separations
    EXPECT_TRUE(fs::exists(out / "stereo.png"));
    EXPECT_TRUE(fs::exists(out / "stereo.md"));
    std::ifstream f(out / "stereo.csv");
    std::string header, line;
    std::getline(f, header);
    for (const char* col : {"scene", "eye_separation", "first_eye_seconds", "second_eye_seconds",
                            "second_eye_new_samples_pct"})
        EXPECT_NE(header.find(col), std::string::npos) << col;
    while (std::getline(f, line)) {
        std::vector<std::string> v;
        std::stringstream ss(line);
        for (std::string cell; std::getline(ss, cell, ',');) v.push_back(cell);
        ASSERT_GE(v.size(), 14u) << line;
        EXPECT_GT(std::stod(v[6]), 0.0) << line;  // first eye seconds
        if (std::stod(v[4]) == 0.0) {             // zero separation: (almost) no new samples
            EXPECT_LT(std::stod(v[13]), 1.0) << line;
        }
    }
}

TEST(TemporalExperiment, UnknownSceneListsTheValidOnes) {
    const CliRun r =
        Texcache("experiment temporal --quick --only anim_shadow,teapot --out " +
                 (fs::path(::testing::TempDir()) / "texcache_exp_temporal_bad").string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("no animated scene named 'teapot'"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("anim_disocclusion"), std::string::npos) << r.out;
}

TEST(ExperimentCli, UnknownNameListsTheValidOnes) {
    const CliRun r = Texcache("experiment fastest --quick --out " +
                              (fs::path(::testing::TempDir()) / "texcache_exp_bad").string());
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_NE(r.out.find("unknown experiment 'fastest'"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("speed-vs-error"), std::string::npos) << r.out;
}

}  // namespace
