// tools/accuracy_table.py: its interpolation by hand, and a quick run whose table holds the
// metrics of the images it wrote.

#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace voxcone {
namespace {

class AccuracyTable : public test::TempDirTest {};

const std::string kTool = test::sourceDir() + "/tools/accuracy_table.py";

TEST_F(AccuracyTable, InterpolationByHand) {
  // Log-log between (1, 10) and (4, 40): at 2, exp(log 10 + (log 2 / log 4) log 4) = 20. Linear
  // in x, log in y between (30, 1) and (40, 100): at 35, 10. Outside: extrapolated and flagged.
  const std::string script = "import sys; sys.path.insert(0, '" + test::sourceDir() +
                             "/tools'); import accuracy_table as a; "
                             "p = [{'x': 4.0, 'y': 40.0}, {'x': 1.0, 'y': 10.0}]; "
                             "q = [{'x': 30.0, 'y': 1.0}, {'x': 40.0, 'y': 100.0}]; "
                             "r = [a.interpolate(p, 2.0, 'x', 'y', True, True), a.interpolate(q, 35.0, 'x', 'y', False, True), "
                             "a.interpolate(p, 8.0, 'x', 'y', True, True)]; "
                             "print(' '.join('%.9f %s' % v for v in r))";
  const std::string cmd = "/usr/bin/python3 -c \"" + script + "\" > " + path("out.txt");
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::ifstream f(path("out.txt"));
  std::string line;
  std::getline(f, line);
  // 20 (in), 10 (in), 80 (beyond the points: '>').
  EXPECT_EQ(line, "20.000000000 in 10.000000000 in 80.000000000 >");
}

TEST_F(AccuracyTable, QuickRunTablesTheImagesItWrote) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  const std::string ref = path("ref.exr");
  ASSERT_EQ(std::system((cli + " render " + scene + " --res 24x24 --spp 64 -q -o " + ref + " > /dev/null").c_str()), 0);
  const std::string cmd = "/usr/bin/python3 " + kTool + " " + scene + " " + ref + " " + path("out") +
                          " --quick --repeat 1 --res 24x24 --threads 1 --figure-photons 5000 --bin " + cli + " > /dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::ifstream f(path("out/table.json"));
  const nlohmann::json t = nlohmann::json::parse(f);
  const Image reference = readImage(ref);
  // voxcone 1 and 4 spp, pm, path 1, 4, 16 spp with each sampler; with the denoiser's weights
  // fetched, voxcone+denoise 1 spp and path+denoise 1 and 4 spp.
  const bool denoise = std::filesystem::exists(test::sourceDir() + "/data/models/oidn/rt_hdr_alb_nrm.tza");
  ASSERT_EQ(t["rows"].size(), denoise ? 12u : 9u);
  int paths = 0, independent = 0, denoisedPaths = 0;
  for (const nlohmann::json& r : t["rows"]) {
    // The tabled metrics are those of the image the row wrote.
    const ImageMetrics m = compareImages(readImage(r["exr"].get<std::string>()), reference);
    EXPECT_NEAR(r["relmse"].get<double>(), m.relMse, 1e-9 * m.relMse);
    EXPECT_NEAR(r["psnr_srgb8"].get<double>(), m.psnrSrgb8, 1e-9);
    EXPECT_GT(r["seconds"].get<double>(), 0.0);
    if (r["method"] == "path") {
      ++paths;
      independent += r["sampler"] == "independent";
      EXPECT_FALSE(r.contains("path_seconds_same_relmse"));
    } else if (r["method"] == "path+denoise") {
      ++denoisedPaths;
      EXPECT_FALSE(r.contains("path_seconds_same_relmse"));
    } else {
      EXPECT_GT(r["path_seconds_same_relmse"].get<double>(), 0.0);
    }
  }
  EXPECT_EQ(paths, 6);
  EXPECT_EQ(independent, 3);
  EXPECT_EQ(denoisedPaths, denoise ? 2 : 0);
  EXPECT_GT(t["target"]["path_seconds"].get<double>(), 0.0);
  EXPECT_GT(t["target"]["path_independent_seconds"].get<double>(), 0.0);
  EXPECT_NEAR(t["target"]["ratio"].get<double>(),
              t["target"]["voxcone_seconds"].get<double>() / t["target"]["path_seconds"].get<double>(), 1e-9);
  // The figure: pm and voxcone at the same photons, error maps on one scale (the larger 99th
  // percentile of the two).
  const nlohmann::json& fig = t["figure"];
  EXPECT_EQ(fig["photons"], 5000);
  double p99 = 0.0;
  for (const nlohmann::json& r : fig["renders"]) {
    EXPECT_EQ(r["options"]["photons"], 5000);
    p99 = std::max(p99, compareImages(readImage(r["exr"].get<std::string>()), reference).relErrorP99);
    EXPECT_EQ(readImage(r["error_png"].get<std::string>()).width, 24);
  }
  EXPECT_NEAR(fig["error_scale"].get<double>(), p99, 1e-9 * p99);
  EXPECT_TRUE(std::filesystem::exists(path("out/table.md")));
}

}  // namespace
}  // namespace voxcone
