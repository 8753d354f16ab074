// tools/block_check.py: block ratios, the worst block and the exit status on images made by hand.

#include "voxcone/image/image_io.h"

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <sys/wait.h>

namespace voxcone {
namespace {

class BlockCheck : public test::TempDirTest {
protected:
  /// Runs the tool on test.exr against ref.exr with `args`; its exit status, stdout in `out`.
  int run(const std::string& args, std::string& out) const {
    const std::string cmd = "/usr/bin/python3 " + test::sourceDir() + "/tools/block_check.py " + path("test.exr") + " " +
                            path("ref.exr") + " --voxcone " + VOXCONE_CLI_PATH + " " + args + " > " + path("out.txt");
    const int status = std::system(cmd.c_str());
    std::ifstream f(path("out.txt"));
    std::stringstream ss;
    ss << f.rdbuf();
    out = ss.str();
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
};

TEST_F(BlockCheck, RatiosWorstBlockAndExitStatusByHand) {
  if (!std::filesystem::exists(VOXCONE_CLI_PATH)) GTEST_SKIP() << "no CLI at " << VOXCONE_CLI_PATH;
  // An 8 x 8 grey reference; the test 1.2 times it in the top-left 4 x 4 block: with a 2 x 2 grid
  // the blocks are 1.2, 1, 1, 1 and the image mean 1.05.
  Image ref(8, 8, Vec3(0.25f)), test = ref;
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) test.at(x, y) = Vec3(0.3f);
  writeExr(path("ref.exr"), ref, nlohmann::json::object());
  writeExr(path("test.exr"), test, nlohmann::json::object());
  std::string out;
  EXPECT_EQ(run("--grid 2", out), 1) << out;  // the mean beyond 2%, a block beyond 5%
  EXPECT_NE(out.find("image mean ratio 1.0500"), std::string::npos) << out;
  EXPECT_NE(out.find("worst 1.2000 at x 0-4, y 0-4; 1 outside"), std::string::npos) << out;
  EXPECT_EQ(run("--grid 2 --mean-tol 0.06 --block-tol 0.25", out), 0) << out;
  EXPECT_EQ(run("--grid 2 --mean-tol 0.06 --block-tol 0.15", out), 1) << out;  // the block alone
}

}  // namespace
}  // namespace voxcone
