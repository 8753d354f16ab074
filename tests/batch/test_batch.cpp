// The batch layer without the executable: manifest expansion and names, shards, the Slurm
// script, sbatch's job id, and the merge of what shards left (outputs written here by hand).

#include "voxcone/batch/batch.h"
#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <fstream>
#include <set>

namespace voxcone {
namespace {

namespace fs = std::filesystem;

class BatchLayer : public test::TempDirTest {
protected:
  nlohmann::json manifest() const {
    return {{"defaults", {{"scene", test::sourceDir() + "/data/scenes/cornell-box.json"}, {"res", "8x8"}}},
            {"jobs", {{{"name", "first"}, {"method", "path"}, {"spp", 2}}}},
            {"grid", {{"method", "voxcone"}, {"spp", {1, 2}}, {"options", {{"level", {4, 5}}}}}}};
  }
  /// What a finished render leaves: an EXR of the size its sidecar records, the sidecar.
  void writeOutputs(const std::string& name, int spp) const {
    writeExr(path(name + ".exr"), Image(8, 8), nullptr);
    std::ofstream(path(name + ".json"))
        << nlohmann::json{{"settings", {{"width", 8}, {"height", 8}, {"spp", spp}}}, {"method", "path"},
                          {"timings", {{"total_seconds", 0.5}}}}
               .dump();
  }
};

TEST_F(BatchLayer, ManifestsExpandInOrderIntoStableNames) {
  const std::vector<Job> jobs = expandManifest(manifest(), m_dir);
  ASSERT_EQ(jobs.size(), 5u);
  EXPECT_EQ(jobs[0].name, "first");
  // Grid axes in key order ("options" before "spp"), the last fastest.
  EXPECT_EQ(jobs[1].spec["options"]["level"], 4);
  EXPECT_EQ(jobs[1].spec["spp"], 1);
  EXPECT_EQ(jobs[2].spec["spp"], 2);
  EXPECT_EQ(jobs[3].spec["options"]["level"], 5);
  EXPECT_EQ(jobs[1].name.rfind("cornell-box_voxcone_spp1_level4_", 0), 0u) << jobs[1].name;
  // The name is the spec's: the same spec, the same name; any other value, another.
  EXPECT_EQ(jobName(jobs[1].spec), jobs[1].name);
  nlohmann::json other = jobs[1].spec;
  other["seed"] = 9;
  EXPECT_NE(jobName(other), jobs[1].name);
  std::set<std::string> names;
  for (const Job& j : jobs) EXPECT_TRUE(names.insert(j.name).second);
  // Unknown keys and a job named twice are errors naming where.
  nlohmann::json bad = manifest();
  bad["jobs"][0]["sppp"] = 3;
  EXPECT_THROW(expandManifest(bad, m_dir), SettingsError);
  bad = manifest();
  bad["jobs"].push_back(bad["jobs"][0]);
  EXPECT_THROW(expandManifest(bad, m_dir), SettingsError);
}

TEST_F(BatchLayer, ShardsCoverTheJobsOnce) {
  const std::vector<Job> jobs = expandManifest(manifest(), m_dir);
  EXPECT_EQ(parseShard("1/3"), std::make_pair(size_t(1), size_t(3)));
  for (const char* bad : {"3/3", "1/0", "-1/2", "1", "a/b", "1/2/3"}) EXPECT_THROW(parseShard(bad), SettingsError) << bad;
  std::multiset<std::string> seen;
  for (size_t i = 0; i < 3; ++i)
    for (const Job& j : shardJobs(jobs, i, 3)) seen.insert(j.name);
  ASSERT_EQ(seen.size(), jobs.size());
  for (const Job& j : jobs) EXPECT_EQ(seen.count(j.name), 1u);
  EXPECT_EQ(shardJobs(jobs, 1, 3).front().name, jobs[1].name);
  EXPECT_EQ(shardJobs(jobs, 1, 3).back().name, jobs[4].name);
}

TEST_F(BatchLayer, SlurmScriptAndJobId) {
  SlurmSettings slurm;
  slurm.shards = 9;  // more than jobs: one task per job
  slurm.arrayLimit = 2;
  BatchSettings batch;
  batch.executable = "/opt/voxcone/bin/voxcone";
  batch.threadsPerJob = 4;
  const std::string script = slurmScript(slurm, batch, "/data/m.json", "/scratch/out", 5);
  EXPECT_EQ(slurmShards(slurm, 5), 5u);
  EXPECT_EQ(script.rfind("#!/bin/sh\n", 0), 0u);
  EXPECT_NE(script.find("#SBATCH --array=0-4%2\n"), std::string::npos) << script;
  EXPECT_NE(script.find("#SBATCH --output=/scratch/out/slurm/%x-%A_%a.log\n"), std::string::npos) << script;
  EXPECT_NE(script.find("#SBATCH --cpus-per-task=4\n"), std::string::npos) << script;
  EXPECT_EQ(script.find("--partition"), std::string::npos);
  EXPECT_NE(script.find("exec '/opt/voxcone/bin/voxcone' batch '/data/m.json' -o '/scratch/out' "
                        "--shard \"${SLURM_ARRAY_TASK_ID}/5\" --skip-existing"),
            std::string::npos)
      << script;
  EXPECT_EQ(parseSbatchJobId("4242\n"), "4242");
  EXPECT_EQ(parseSbatchJobId("4242;cluster-a\n"), "4242");
  EXPECT_THROW(parseSbatchJobId("sbatch: error: Batch job submission failed\n"), Error);
}

TEST_F(BatchLayer, MergeTakesOutputsOverTablesAndNamesWhatIsMissing) {
  const std::vector<Job> jobs = expandManifest(manifest(), m_dir);
  // Shard 0 of 2 (jobs 0, 2, 4) finished; its table says so. Shard 1 (jobs 1, 3) was killed after
  // job 1's render but before its table was written; job 3 failed in an earlier run.
  for (size_t k : {0, 2, 4}) writeOutputs(jobs[k].name, 2);
  writeOutputs(jobs[1].name, 1);
  std::vector<nlohmann::json> rows0, rows1;
  for (size_t k : {0, 2, 4}) rows0.push_back(resultRow(jobs[k], {"ok", "", nullptr, nullptr}));
  writeTables(rows0, path("results-shard-0-of-2"), nlohmann::json::object());
  rows1.push_back(resultRow(jobs[1], {"interrupted", "stopped by SIGTERM", nullptr, nullptr}));
  rows1.push_back(resultRow(jobs[3], {"failed", "out of memory", nullptr, nullptr}));
  writeTables(rows1, path("results-shard-1-of-2"), nlohmann::json::object());

  MergeReport r = mergeShards(jobs, m_dir);
  ASSERT_EQ(r.rows.size(), 5u);
  for (size_t k = 0; k < 5; ++k) EXPECT_EQ(r.rows[k]["name"], jobs[k].name);  // manifest order
  EXPECT_EQ(r.rows[1]["status"], "ok");      // its outputs are complete: the table is stale
  EXPECT_EQ(r.rows[1]["resolved_spp"], 1);   // read from its sidecar
  EXPECT_EQ(r.rows[3]["status"], "failed");
  EXPECT_EQ(r.rows[3]["error"], "out of memory");
  EXPECT_EQ(r.counts["ok"], 4u);
  ASSERT_EQ(r.notComplete.size(), 1u);
  EXPECT_EQ(r.notComplete[0], jobs[3].name + ": failed (out of memory)");
  // An output lost since the table said ok: missing.
  fs::remove(path(jobs[2].name + ".exr"));
  r = mergeShards(jobs, m_dir);
  EXPECT_EQ(r.rows[2]["status"], "missing");
  EXPECT_EQ(r.rows[2]["error"], "its outputs are gone or incomplete");
  // Nothing at all: every job missing, never run.
  r = mergeShards(jobs, m_dir / "empty");
  EXPECT_EQ(r.counts["missing"], 5u);
  EXPECT_EQ(r.rows[0]["error"], "no shard has run it");
}

}  // namespace
}  // namespace voxcone
