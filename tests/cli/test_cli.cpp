// The `voxcone` executable end to end: outputs, sidecar, and one-line errors with a non-zero
// exit and no output for bad input.

#include "../support/test_scenes.h"
#include "voxcone/image/image_io.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <xxhash.h>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace voxcone {
namespace {

namespace fs = std::filesystem;

struct RunResult {
  int code;
  std::string err;
};

RunResult run(const std::string& args) {
  // One file per test process: ctest runs the tests side by side, and a shared name mixed
  // their messages.
  const std::string errFile = ::testing::TempDir() + "/cli_stderr-" + std::to_string(::getpid()) + ".txt";
  const std::string cmd = std::string(VOXCONE_CLI_PATH) + " " + args + " >/dev/null 2>" + errFile;
  const int status = std::system(cmd.c_str());
  std::ifstream f(errFile);
  std::string err((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, err};
}

fs::path freshDir(const std::string& name) {
  const fs::path d = fs::path(::testing::TempDir()) / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

/// Start `voxcone ARGS...` (stdout and stderr to files in `dir`); returns its pid.
pid_t spawn(const std::vector<std::string>& args, const fs::path& dir) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    std::freopen((dir / "stdout.txt").c_str(), "w", stdout);
    std::freopen((dir / "stderr.txt").c_str(), "w", stderr);
    std::vector<char*> argv = {const_cast<char*>(VOXCONE_CLI_PATH)};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(VOXCONE_CLI_PATH, argv.data());
    ::_exit(127);
  }
  return pid;
}

/// CPU seconds process `pid` has used (user + system), from /proc.
double cpuSeconds(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string stat((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const size_t close = stat.rfind(')');
  if (close == std::string::npos) return 0.0;
  std::istringstream rest(stat.substr(close + 2));
  std::string field;
  double ticks = 0.0;
  for (int i = 3; i <= 15 && rest >> field; ++i)
    if (i == 14 || i == 15) ticks += std::stod(field);  // utime, stime
  return ticks / double(::sysconf(_SC_CLK_TCK));
}

/// Wait for `pid` (up to a minute, so that a slow machine passes) and return its exit status,
/// -1 when it did not exit.
int waitExit(pid_t pid) {
  int status = 0;
  for (int i = 0; i < 600; ++i) {
    if (::waitpid(pid, &status, WNOHANG) == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    ::usleep(100000);
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, &status, 0);
  return -1;
}

/// CPU seconds `voxcone --version` takes (the largest of three runs): the dynamic loader and
/// static initialisation, before main installs the signal handlers. 0.4 s on a VM whose page
/// faults are slow, where a signal after a fixed 0.5 CPU seconds sometimes found no handler yet.
double startupCpuSeconds() {
  static const double seconds = [] {
    const fs::path d = freshDir("cli_startup");
    double most = 0.0;
    for (int i = 0; i < 3; ++i) {
      const pid_t pid = spawn({"--version"}, d);
      int status = 0;
      rusage usage{};
      if (::wait4(pid, &status, 0, &usage) != pid) continue;
      most = std::max(most, double(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
                                1e-6 * double(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec));
    }
    return most;
  }();
  return seconds;
}

/// A path-traced render of a million samples per pixel (hours), started and signalled once it
/// has rendered for `cpu` CPU seconds past twice its start-up's (past loading whatever the
/// machine's speed).
pid_t signalledRender(const fs::path& dir, bool writePartial, int sig, double cpu = 0.5) {
  cpu += 2.0 * startupCpuSeconds();
  std::vector<std::string> args = {"render", test::sourceDir() + "/data/scenes/cornell-box.json", "--method", "path",
                                   "--spp", "1000000", "--res", "16x16", "-t", "1", "-q", "-o", (dir / "img").string()};
  if (writePartial) args.push_back("--write-partial");
  const pid_t pid = spawn(args, dir);
  for (int i = 0; i < 600 && cpuSeconds(pid) < cpu; ++i) ::usleep(50000);
  ::kill(pid, sig);
  return pid;
}

TEST(Cli, InterruptedRenderWritesNothingAndSaysSo) {
  // SIGINT / SIGTERM at a million spp (one 16x16 tile: it used to be honoured only between
  // tiles, i.e. never): 128 + the signal, no file, no temporary.
  for (int sig : {SIGINT, SIGTERM}) {
    const fs::path d = freshDir("cli_interrupt_" + std::to_string(sig));
    const int code = waitExit(signalledRender(d, false, sig));
    EXPECT_EQ(code, 128 + sig);
    std::ifstream f(d / "stderr.txt");
    const std::string err((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    EXPECT_NE(err.find("interrupted; no output written"), std::string::npos) << err;
    for (const auto& e : fs::directory_iterator(d))
      EXPECT_TRUE(e.path().filename() == "stdout.txt" || e.path().filename() == "stderr.txt") << e.path();
  }
}

TEST(Cli, WritePartialWritesTheCompletePassesAsAnImageOfFewerSamples) {
  const fs::path d = freshDir("cli_partial");
  const int code = waitExit(signalledRender(d, true, SIGTERM));
  EXPECT_EQ(code, 128 + SIGTERM);  // still "interrupted", with the image written
  std::ifstream f(d / "img.json");
  ASSERT_TRUE(f) << "no sidecar";
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j.value("partial", false), true);
  EXPECT_EQ(j["requested_spp"], 1000000);
  const int spp = j["settings"]["spp"];
  EXPECT_GE(spp, 1);
  EXPECT_LT(spp, 1000000);
  // Passes of 1, 1, 2, 4, ... 64: spp is a sum of whole passes.
  int sum = 0, next = 1, passes = 0;
  while (sum < spp) {
    sum += next;
    if (++passes > 1) next = std::min(2 * next, 64);
  }
  EXPECT_EQ(sum, spp);
  // The partial image is the render of that many samples, bit for bit.
  const RunResult full = run("render " + test::sourceDir() + "/data/scenes/cornell-box.json --method path --res 16x16 -t 2 -q --spp " +
                             std::to_string(spp) + " -o " + (d / "full").string());
  ASSERT_EQ(full.code, 0) << full.err;
  const Image a = readImage((d / "img.exr").string()), b = readImage((d / "full.exr").string());
  EXPECT_TRUE(a.pixels == b.pixels);
}

TEST(Cli, RenderWritesExrPngAndSidecar) {
  const fs::path d = freshDir("cli_render");
  const RunResult r = run("render " + test::sourceDir() + "/data/scenes/cornell-box.json -q --res 24x16 --spp 2 -t 2 --seed 7 -o " +
                          (d / "img").string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(d / "img.exr"));
  EXPECT_TRUE(fs::exists(d / "img.png"));
  std::ifstream f(d / "img.json");
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j["settings"]["width"], 24);
  EXPECT_EQ(j["settings"]["height"], 16);
  EXPECT_EQ(j["seed"], 7);
  EXPECT_EQ(j["method"], "voxcone");  // every canonical scene renders with voxcone by default
  EXPECT_GT(j["timings"]["render_seconds"].get<double>(), 0.0);
  EXPECT_GT(j["peak_rss_bytes"].get<double>(), 0.0);
  EXPECT_EQ(j["stats"]["scene"]["triangles"], 32);
  // Nothing else (no temporary files) is left in the folder.
  EXPECT_EQ(std::distance(fs::directory_iterator(d), fs::directory_iterator()), 3);
}

/// Standard output of `voxcone ARGS` (stderr discarded) and its exit status.
std::pair<int, std::string> runStdout(const std::string& args) {
  FILE* p = ::popen((std::string(VOXCONE_CLI_PATH) + " " + args + " 2>/dev/null").c_str(), "r");
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int status = ::pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

/// XXH3-128 of a whole file read at once, as `xxhsum -H2` prints it (not the streaming code
/// the renderer uses).
std::string wholeFileXxh128(const fs::path& file) {
  std::ifstream f(file, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  const XXH128_hash_t h = XXH3_128bits(bytes.data(), bytes.size());
  char hex[33];
  std::snprintf(hex, sizeof hex, "%016llx%016llx", (unsigned long long)h.high64, (unsigned long long)h.low64);
  return hex;
}

TEST(Cli, VersionIsTheProjectsAndHelpShowsDefaults) {
  const auto [code, out] = runStdout("--version");
  EXPECT_EQ(code, 0);
  EXPECT_EQ(out.rfind(std::string("voxcone ") + VOXCONE_PROJECT_VERSION + " (", 0), 0u) << out;
  const auto [hcode, help] = runStdout("render --help");
  EXPECT_EQ(hcode, 0);
  for (const char* shown : {"--spp INT:INT in [1 - 16777216]=the scene's", "--accel TEXT:{", "=hbvh",
                            "-t,--threads INT:INT in [0 - 4096]=0", "-o,--output TEXT:NONEMPTY=out/<scene>"})
    EXPECT_NE(help.find(shown), std::string::npos) << shown << " not in:\n" << help;
  const auto [vcode, vhelp] = runStdout("voxelize --help");
  EXPECT_NE(vhelp.find("--level INT:INT in [1 - 13]=8"), std::string::npos) << vhelp;
  EXPECT_EQ(vhelp.find("=-1"), std::string::npos) << "a sentinel shown as a default:\n" << vhelp;
}

TEST(Cli, SidecarAndImagesRecordWhatTheImageWasMadeFrom) {
  // The full command line, the absolute scene path and a content hash of the scene and of
  // every mesh it loads; the EXR's attributes typed, the PNG's as text.
  const fs::path d = freshDir("cli_provenance");
  std::ofstream(d / "tri.obj") << "v -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n";
  std::ofstream(d / "scene.json") << R"({"camera": {"position": [0,0,-3], "target": [0,0,0], "fov_y_deg": 40},
    "render": {"width": 8, "height": 8, "spp": 1, "method": "path"},
    "materials": {"m": {"type": "lambertian", "albedo": 0.5, "emission": 1, "two_sided_emission": true}},
    "shapes": [{"type": "mesh", "file": "tri.obj", "material": "m"}]})";
  const std::vector<std::string> args = {"render", "scene.json", "-q", "--seed", "3", "-o", (d / "img.exr").string()};
  std::string line;
  for (const std::string& a : args) line += " " + a;
  // From the scene's folder, the scene named relatively.
  const int status = std::system(("cd " + d.string() + " && " + VOXCONE_CLI_PATH + line).c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  std::ifstream f(d / "img.json");
  const nlohmann::json j = nlohmann::json::parse(f);
  std::vector<std::string> expected = {VOXCONE_CLI_PATH};
  expected.insert(expected.end(), args.begin(), args.end());
  EXPECT_EQ(j["command_line"].get<std::vector<std::string>>(), expected);
  EXPECT_EQ(j["working_directory"], fs::canonical(d).string());
  EXPECT_EQ(j["scene"], (fs::canonical(d) / "scene.json").string());
  EXPECT_EQ(j["voxcone_version"], VOXCONE_PROJECT_VERSION);
  ASSERT_EQ(j["inputs"].size(), 2u) << j["inputs"];
  EXPECT_EQ(j["inputs"][0]["role"], "scene");
  EXPECT_EQ(j["inputs"][0]["xxh128"], wholeFileXxh128(d / "scene.json"));
  EXPECT_EQ(j["inputs"][0]["bytes"], fs::file_size(d / "scene.json"));
  EXPECT_EQ(j["inputs"][1]["role"], "mesh");
  EXPECT_EQ(j["inputs"][1]["path"], (fs::canonical(d) / "tri.obj").string());
  EXPECT_EQ(j["inputs"][1]["xxh128"], wholeFileXxh128(d / "tri.obj"));
  auto exr = OIIO::ImageInput::open((d / "img.exr").string());
  ASSERT_TRUE(exr);
  const OIIO::ParamValue* spp = exr->spec().find_attribute("voxcone:settings.spp");
  ASSERT_NE(spp, nullptr);
  EXPECT_EQ(spp->type(), OIIO::TypeInt);
  EXPECT_EQ(exr->spec().get_string_attribute("voxcone:method"), "path");
  auto png = OIIO::ImageInput::open((d / "img.png").string());
  ASSERT_TRUE(png);
  EXPECT_EQ(png->spec().get_string_attribute("voxcone:settings.seed"), "3");
  EXPECT_EQ(png->spec().get_string_attribute("Software"), std::string("voxcone ") + VOXCONE_PROJECT_VERSION);
  // A Mitsuba scene: its XML and each OBJ it loads.
  const RunResult x = run("render " + test::sourceDir() + "/data/scenes/cornell-box.xml -q --res 8x8 --spp 1 -o " +
                          (d / "xml").string());
  ASSERT_EQ(x.code, 0) << x.err;
  std::ifstream fx(d / "xml.json");
  const nlohmann::json jx = nlohmann::json::parse(fx);
  ASSERT_EQ(jx["inputs"].size(), 8u) << jx["inputs"];
  EXPECT_EQ(jx["inputs"][0]["role"], "scene");
  EXPECT_EQ(jx["inputs"][1]["role"], "mesh");
  EXPECT_EQ(jx["inputs"][1]["xxh128"], wholeFileXxh128(jx["inputs"][1]["path"].get<std::string>()));
}

TEST(Cli, AovLayersAndTypedAttributesAsOiiotoolShowsThem) {
  const fs::path d = freshDir("cli_aov");
  const RunResult r = run("render " + test::sourceDir() + "/data/scenes/cornell-box.json -q --res 16x16 --spp 2 " +
                          "--aov albedo,normal,depth,emitted,direct,indirect,caustic -o " + (d / "img").string());
  ASSERT_EQ(r.code, 0) << r.err;
  auto in = OIIO::ImageInput::open((d / "img.exr").string());
  ASSERT_TRUE(in);
  std::vector<std::string> names = in->spec().channelnames;
  std::sort(names.begin(), names.end());
  const std::vector<std::string> expected = {
      "Albedo.B", "Albedo.G", "Albedo.R", "B", "Caustic.B", "Caustic.G", "Caustic.R", "Direct.B", "Direct.G",
      "Direct.R", "Emitted.B", "Emitted.G", "Emitted.R", "G", "Indirect.B", "Indirect.G", "Indirect.R",
      "Ns.X", "Ns.Y", "Ns.Z", "R", "Z"};
  EXPECT_EQ(names, expected);
  std::ifstream f(d / "img.json");
  EXPECT_EQ(nlohmann::json::parse(f)["aovs"]["depth"], nlohmann::json::array({"Z"}));
  if (std::system("command -v oiiotool >/dev/null 2>&1") != 0) GTEST_SKIP() << "oiiotool not installed";
  FILE* p = ::popen(("oiiotool --info -v " + (d / "img.exr").string()).c_str(), "r");
  std::string info;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) info.append(buf, n);
  ::pclose(p);
  // oiiotool quotes strings and prints numbers bare: typed, not JSON text.
  for (const char* shown : {"22 channel", "Albedo.R", "Ns.X", "Z", "voxcone:method: \"voxcone\"",
                            "voxcone:settings.spp: 2", "voxcone:settings.width: 16"})
    EXPECT_NE(info.find(shown), std::string::npos) << shown << " not in:\n" << info;
}

TEST(Cli, SamplerIsChosenAndRecorded) {
  // --sampler picks the pixel sampler and the sidecar says which; the two give different images
  // of the same scene and seed.
  const fs::path d = freshDir("cli_sampler");
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  for (const char* sampler : {"sobol", "independent"}) {
    const RunResult r = run("render " + scene + " --method path -q --res 16x16 --spp 4 --sampler " + sampler +
                            " -o " + (d / sampler).string());
    ASSERT_EQ(r.code, 0) << r.err;
    std::ifstream f(d / (std::string(sampler) + ".json"));
    EXPECT_EQ(nlohmann::json::parse(f)["settings"]["sampler"], sampler);
  }
  const Image a = readImage((d / "sobol.exr").string()), b = readImage((d / "independent.exr").string());
  EXPECT_NE(a.pixels, b.pixels);
}

TEST(Cli, LightSplitIsChosenAndRecorded) {
  // --light-split sets the tree's split angle and the sidecar records it; on many-lights
  // splitting changes the image (more light samples where lights are near), and 0 is the
  // tree's single choice.
  const fs::path d = freshDir("cli_light_split");
  const std::string scene = test::sourceDir() + "/data/scenes/failure/many-lights.json";
  for (const char* split : {"0", "45"}) {
    const RunResult r = run("render " + scene + " --method path -q --res 16x16 --spp 2 --light-split " + split + " -o " +
                            (d / split).string());
    ASSERT_EQ(r.code, 0) << r.err;
    std::ifstream f(d / (std::string(split) + ".json"));
    EXPECT_EQ(nlohmann::json::parse(f)["settings"]["light_split"].get<double>(), std::stod(split));
  }
  EXPECT_NE(readImage((d / "0.exr").string()).pixels, readImage((d / "45.exr").string()).pixels);
}

TEST(Cli, DenoiseTakesTheRendersLayersAndRenderDenoiseGivesTheSameImage) {
  // `denoise` finds the Albedo and Ns layers of `render --aov albedo,normal`; `render
  // --denoise` runs the same network on the same beauty and layers, so the images are equal;
  // its sidecar records the weights and the time, and it writes no layer it was not asked for.
  if (!fs::exists(test::sourceDir() + "/data/models/oidn/rt_hdr_alb_nrm.tza"))
    GTEST_SKIP() << "run tools/fetch_models.sh to fetch the denoiser's weights";
  const fs::path d = freshDir("cli_denoise");
  const std::string common = "render --method path -q --res 40x24 --spp 4 -o ";
  ASSERT_EQ(run(common + (d / "raw").string() + " --aov albedo,normal").code, 0);
  const RunResult den = run("denoise " + (d / "raw.exr").string() + " -o " + (d / "den.exr").string());
  ASSERT_EQ(den.code, 0) << den.err;
  const RunResult both = run(common + (d / "both").string() + " --denoise");
  ASSERT_EQ(both.code, 0) << both.err;
  const Image a = readImage((d / "den.exr").string()), b = readImage((d / "both.exr").string());
  EXPECT_TRUE(a.pixels == b.pixels);
  EXPECT_NE(a.pixels, readImage((d / "raw.exr").string()).pixels);
  std::ifstream f(d / "both.json");
  const nlohmann::json meta = nlohmann::json::parse(f);
  EXPECT_EQ(meta["denoise"]["weights"], "rt_hdr_alb_nrm.tza");
  EXPECT_GT(meta["timings"]["denoise_seconds"].get<double>(), 0.0);
  EXPECT_FALSE(meta.contains("aovs"));
  EXPECT_FALSE(readImageLayers((d / "both.exr").string(), {"Albedo."})[0].has_value());
  EXPECT_TRUE(readImageLayers((d / "raw.exr").string(), {"Albedo."})[0].has_value());
  // voxcone under the denoiser takes a quarter of its photons by default.
  ASSERT_EQ(run("render --method voxcone -q --res 32x32 --spp 1 --denoise -o " + (d / "vd").string()).code, 0);
  std::ifstream fv(d / "vd.json");
  const nlohmann::json vd = nlohmann::json::parse(fv);
  EXPECT_EQ(vd["settings"]["integrator"]["photon_target"], 50000);
  EXPECT_EQ(vd["settings"]["denoise"], true);
  // Colour alone, colour and albedo: other networks, other images.
  ASSERT_EQ(run("denoise " + (d / "raw.exr").string() + " --aux none -o " + (d / "plain.exr").string()).code, 0);
  ASSERT_EQ(run("denoise " + (d / "raw.exr").string() + " --aux albedo -o " + (d / "alb.exr").string()).code, 0);
  const Image plain = readImage((d / "plain.exr").string()), alb = readImage((d / "alb.exr").string());
  EXPECT_NE(plain.pixels, a.pixels);
  EXPECT_NE(alb.pixels, a.pixels);
  EXPECT_NE(alb.pixels, plain.pixels);
}

TEST(Cli, DenoiseBadInputGivesOneLineAndNoOutput) {
  const fs::path d = freshDir("cli_denoise_bad");
  ASSERT_EQ(run("render --method path -q --res 16x16 --spp 1 -o " + (d / "raw").string()).code, 0);
  const std::string raw = (d / "raw.exr").string(), out = (d / "out.exr").string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"denoise " + (d / "missing.exr").string() + " -o " + out, "no such image file"},
      {"denoise " + raw + " -o " + (d / "out.jpg").string(), "unknown extension"},
      {"denoise " + raw + " -o " + out + " --normal " + raw, "needs --albedo"},
      {"denoise " + raw + " -o " + out + " --weights " + (d / "none").string(), "fetch_models.sh"},
      {"denoise " + (d / "raw.png").string() + " -o " + out, "8-bit"},
      {"render --method path -q --res 16x16 --spp 1 --denoise-weights " + d.string() + " -o " + (d / "r2").string(),
       "without --denoise"},
      {"render --method path -q --res 16x16 --spp 1 --denoise --denoise-weights " + (d / "none").string() + " -o " +
           (d / "r3").string(),
       "fetch_models.sh"},
  };
  for (const auto& [args, says] : cases) {
    const RunResult r = run(args);
    EXPECT_NE(r.code, 0) << args;
    EXPECT_NE(r.err.find(says), std::string::npos) << args << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(d / "r2.exr"));
  EXPECT_FALSE(fs::exists(d / "r3.exr"));
}

TEST(Cli, BadInputGivesOneLineAndNoOutput) {
  const fs::path d = freshDir("cli_bad");
  const std::string scenes = test::sourceDir() + "/data/scenes/";
  {
    std::ofstream(d / "broken.json") << "{\"camera\": ";
    std::ofstream(d / "binary.json") << std::string("\xff\xfe\x01\x02{", 5);
    std::ofstream(d / "badmesh.json") << R"({"camera": {"position": [0,0,-1], "target": [0,0,0]},
      "materials": {"m": {"type": "lambertian", "emission": 1}},
      "shapes": [{"type": "mesh", "file": "missing.obj", "material": "m"}]})";
  }
  const std::vector<std::string> bad = {
      "render /nonexistent.json -q -o " + (d / "a").string(),
      "render " + (d / "broken.json").string() + " -q -o " + (d / "b").string(),
      "render " + (d / "binary.json").string() + " -q -o " + (d / "b2").string(),
      "render " + (d / "badmesh.json").string() + " -q -o " + (d / "c").string(),
      "render " + scenes + "cornell-box.json -q --method nope -o " + (d / "d").string(),
      "render " + scenes + "cornell-box.json -q --res 0x10 -o " + (d / "e").string(),
      "render " + scenes + "cornell-box.json -q --res banana -o " + (d / "f").string(),
      "render " + scenes + "cornell-box.json -q --options '{\"x\":1}' -o " + (d / "g").string(),
      "render " + scenes + "cornell-box.json -q --sampler halton -o " + (d / "h").string(),
      "render " + scenes + "cornell-box.json -q --light-sampler bvh -o " + (d / "h2").string(),
      "render " + scenes + "cornell-box.json -q --light-split 91 -o " + (d / "h3").string(),
      "render " + scenes + "cornell-box.json -q --light-split -5 -o " + (d / "h4").string(),
      "render " + scenes + "cornell-box.json -q -o /nonexistent-dir/x",
      // Not clamped to 2^63 - 1, not taken as "not given".
      "render " + scenes + "cornell-box.json -q --seed 99999999999999999999 -o " + (d / "i").string(),
      "render " + scenes + "cornell-box.json -q --seed -1 -o " + (d / "j").string(),
      "render " + scenes + "cornell-box.json -q --method '' -o " + (d / "k").string(),
      "render " + scenes + "cornell-box.json -q -o ''",
      "render " + scenes + "cornell-box.json -q --aov albedo,beauty -o " + (d / "q").string(),
      "render " + scenes + "cornell-box.json -q --method pm --aov direct -o " + (d / "r").string(),
      // Was written as x.tiff.exr, x.tiff.png, x.tiff.json.
      "render " + scenes + "cornell-box.json -q -o " + (d / "p.tiff").string(),
      "info /nonexistent.json",
      "compare /nonexistent1.exr /nonexistent2.exr",
      // Usage errors (CLI11 exited 105-114 with a second "Run with --help" line).
      "",
      "render --bogus",
      "render " + scenes + "cornell-box.json -q --spp 0 -o " + (d / "l").string(),
      "render " + scenes + "cornell-box.json -q --spp lots -o " + (d / "m").string(),
      "voxelize",
      "voxelize " + scenes + "cornell-box.json --level 14",
      // CLI::PositiveNumber printed DBL_MAX's 309 digits as the bound.
      "render " + scenes + "cornell-box.json -q --target-error -1 -o " + (d / "n").string(),
      "render " + scenes + "cornell-box.json -q --time-budget abc -o " + (d / "o").string(),
      "study",
      "batch",
  };
  for (const std::string& args : bad) {
    const RunResult r = run(args);
    EXPECT_EQ(r.code, 2) << args << ": " << r.err;
    EXPECT_FALSE(r.err.empty()) << args;
    // One line of error, printable: no control bytes and none of a binary file's bytes echoed
    // back.
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << ": " << r.err;
    EXPECT_LT(r.err.size(), 300u) << args << ": " << r.err;
    for (char c : r.err)
      EXPECT_TRUE(c == '\n' || (c >= 32 && c < 127)) << args << ": byte " << int(static_cast<unsigned char>(c));
  }
  // Only the three input files remain: no output, no temporaries.
  EXPECT_EQ(std::distance(fs::directory_iterator(d), fs::directory_iterator()), 3);
  // Help and version succeed.
  for (const char* args : {"--help", "render --help", "--version"}) EXPECT_EQ(run(args).code, 0) << args;
}

TEST(Cli, CompareRefusesAFloatImageAgainstAnEightBitOne) {
  // A render's EXR against its own PNG measured the PNG's clipping (relMSE 0.55, PSNR inf).
  const fs::path d = freshDir("cli_compare_kinds");
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  ASSERT_EQ(run("render " + scene + " -q --res 8x8 --spp 1 -o " + (d / "a").string()).code, 0);
  const RunResult r = run("compare " + (d / "a.exr").string() + " " + (d / "a.png").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("8-bit display-encoded"), std::string::npos) << r.err;
  EXPECT_EQ(run("compare " + (d / "a.png").string() + " " + (d / "a.png").string()).code, 0);
}

TEST(Cli, OutputsThatCannotBeWrittenFailBeforeTheRender) {
  // A directory where the PNG goes, or -o naming a folder: refused before any work, nothing
  // written (they used to fail after the render, the EXR left behind).
  const fs::path d = freshDir("cli_outputs");
  fs::create_directories(d / "x.png");
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  for (const std::string& out : {(d / "x").string(), d.string() + "/"}) {
    const RunResult r = run("render " + scene + " -q --res 8x8 --spp 1 -o " + out);
    EXPECT_EQ(r.code, 2) << out;
    EXPECT_NE(r.err.find(out.back() == '/' ? "names a folder" : "is a directory"), std::string::npos) << r.err;
  }
  EXPECT_EQ(std::distance(fs::directory_iterator(d), fs::directory_iterator()), 1);  // x.png/ alone
  // A folder nothing can be written into (a read-only one refuses only other users than root,
  // which the tests may run as; /proc refuses everyone).
  const RunResult r = run("render " + scene + " -q --res 8x8 --spp 1 -o /proc/voxcone-x");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("cannot write into /proc"), std::string::npos) << r.err;
}

TEST(Cli, InfoPrintsHbvhStatistics) {
  const std::string out = ::testing::TempDir() + "/info.json";
  const std::string cmd = std::string(VOXCONE_CLI_PATH) + " info --json " + test::sourceDir() +
                          "/data/scenes/cornell-box.json > " + out;
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::ifstream f(out);
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j["scene"]["triangles"], 32);
  EXPECT_EQ(j["hbvh"]["triangles"], 32);
  EXPECT_EQ(j["hbvh"]["binary_nodes"].get<int>(), 2 * j["hbvh"]["leaves"].get<int>() - 1);
}

}  // namespace
}  // namespace voxcone
