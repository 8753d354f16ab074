// `voxcone render`, `info` and `convert` on Mitsuba 3 XML scenes: -D, one-line errors with exit
// 2, and the conversion both ways through the executable.

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace voxcone {
namespace {

class MitsubaCli : public test::TempDirTest {
protected:
  struct Result {
    int code;
    std::string out, err;
  };
  Result run(const std::string& args) const {
    const std::string cmd =
        std::string(VOXCONE_CLI_PATH) + " " + args + " > " + path("stdout.txt") + " 2> " + path("stderr.txt");
    const int status = std::system(cmd.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, read("stdout.txt"), read("stderr.txt")};
  }
  std::string read(const std::string& name) const {
    std::ifstream f(path(name));
    return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  }
  static std::string xml() { return test::sourceDir() + "/data/scenes/cornell-box.xml"; }
};

TEST_F(MitsubaCli, RenderTakesDefinesThatOverrideDefaults) {
  // -D before the scene too: each -D takes one value, the scene stays the positional argument.
  const Result r = run("render -D spp=2 " + xml() + " -D res=12 --define max_depth=3 -q -o " + path("img"));
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream f(path("img.json"));
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j["settings"]["width"], 12) << j.dump();
  EXPECT_EQ(j["settings"]["spp"], 2);
  EXPECT_EQ(j["settings"]["max_depth"], 3);
  EXPECT_EQ(j["method"], "path");
  // -D on a JSON scene, or malformed, is one line and exit 2.
  for (const std::string& bad : {"render " + test::sourceDir() + "/data/scenes/cornell-box.json -D spp=2",
                                 "render " + xml() + " -D spp", "render " + xml() + " -D a=1 -D a=2"}) {
    const Result e = run(bad + " -q -o " + path("bad"));
    EXPECT_EQ(e.code, 2) << bad;
    EXPECT_EQ(std::count(e.err.begin(), e.err.end(), '\n'), 1) << e.err;
  }
}

TEST_F(MitsubaCli, UnsupportedPluginExitsTwoWithOneLineNamingIt) {
  std::string text;
  {
    std::ifstream f(xml());
    text.assign((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  }
  // The red wall's BSDF becomes principled (which voxcone does not map), at its line of data/scenes/cornell-box.xml.
  const std::string from = "<bsdf type=\"twosided\" id=\"red\">";
  const size_t at = text.find(from);
  ASSERT_NE(at, std::string::npos);
  const int line = 1 + int(std::count(text.begin(), text.begin() + long(at), '\n'));
  text.replace(at, from.size(), "<bsdf type=\"principled\" id=\"red\">");
  std::filesystem::copy(test::sourceDir() + "/data/scenes/mitsuba", m_dir / "mitsuba");
  const std::string scene = write("principled.xml", text);
  for (const std::string& cmd : {"render " + scene + " -q -o " + path("out"), "info " + scene}) {
    const Result r = run(cmd);
    EXPECT_EQ(r.code, 2) << cmd;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find("principled.xml: line " + std::to_string(line) +
                         ": <bsdf type=\"principled\" id=\"red\">: unsupported BSDF plugin 'principled'"),
              std::string::npos)
        << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(path("out.exr")));
}

TEST_F(MitsubaCli, ConvertBothWaysAndInfoReadsTheResult) {
  Result r = run("convert " + test::sourceDir() + "/data/scenes/cornell-box.json -o " + path("cb.xml"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::is_directory(path("cb_meshes")));
  r = run("convert " + path("cb.xml") + " -o " + path("back.json"));
  ASSERT_EQ(r.code, 0) << r.err;
  r = run("info " + path("back.json") + " --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["scene"]["triangles"], 32) << j.dump();
  // The Mitsuba scene to JSON, with a -D.
  r = run("convert " + xml() + " -D res=20 -o " + path("from-xml.json"));
  ASSERT_EQ(r.code, 0) << r.err;
  std::ifstream f(path("from-xml.json"));
  const nlohmann::json s = nlohmann::json::parse(f);
  EXPECT_EQ(s["render"]["width"], 20);
  EXPECT_EQ(s["materials"]["white"]["albedo"], nlohmann::json({0.725, 0.71, 0.68}));
  // Not .xml or .json, or over its input: exit 2.
  EXPECT_EQ(run("convert " + xml() + " -o " + path("x.obj")).code, 2);
  EXPECT_EQ(run("convert " + path("cb.xml") + " -o " + path("cb.xml")).code, 2);
}

}  // namespace
}  // namespace voxcone
