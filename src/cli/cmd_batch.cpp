// `voxcone batch MANIFEST.json`: the command line of the batch layer (voxcone/batch/batch.h):
// run a manifest's renders here (all, or one shard), submit it to Slurm as a job array, or say
// and merge what its shards wrote.

#include "cli_util.h"
#include "commands.h"
#include "voxcone/batch/batch.h"
#include "voxcone/core/error.h"
#include "voxcone/core/progress.h"

#include <cstdio>

namespace voxcone {

namespace fs = std::filesystem;

namespace {

struct BatchOptions {
  std::string manifestPath;
  std::string outDir;
  std::string shard;
  bool dryRun = false;
  bool slurm = false;
  bool wait = false;
  bool status = false;
  bool merge = false;
  BatchSettings batch;
  SlurmSettings cluster;
};

/// Print what a merge found (and write its table when `write`); exit 1 unless all is complete.
void reportMerge(const Manifest& m, bool write) {
  const MergeReport r = mergeShards(m.jobs, m.outDir);
  const std::string stem = (m.outDir / "results").string();
  if (write) writeTables(r.rows, stem, {{"manifest", m.path}, {"merged", true}});
  auto count = [&](const char* s) { return r.counts.count(s) ? r.counts.at(s) : size_t(0); };
  std::printf("%s: %zu jobs: %zu complete, %zu failed, %zu interrupted, %zu not run, %zu missing%s\n",
              write ? "merge" : "status", m.jobs.size(), count("ok"), count("failed"), count("interrupted"),
              count("not run"), count("missing"), write ? ("; wrote " + stem + ".csv, " + stem + ".json").c_str() : "");
  for (const std::string& line : r.notComplete) std::printf("  %s\n", line.c_str());
  if (!r.notComplete.empty()) throw CLI::RuntimeError(1);
}

void runBatch(const BatchOptions& o) {
  const Manifest m = loadManifest(o.manifestPath, o.outDir);
  if (int(o.slurm) + int(o.status) + int(o.merge) + int(!o.shard.empty()) > 1)
    throw SettingsError("--slurm, --status, --merge and --shard are one at a time");
  if (o.wait && !o.slurm) throw SettingsError("--wait goes with --slurm");
  if (o.status || o.merge) return reportMerge(m, o.merge);
  if (o.slurm) {
    const fs::path outDir = fs::absolute(m.outDir);
    if (o.dryRun) {
      std::printf("%s", slurmScript(o.cluster, o.batch, m.path, outDir, m.jobs.size()).c_str());
      return;
    }
    const auto [id, script] = submitSlurm(o.cluster, o.batch, m.path, outDir, m.jobs.size());
    std::printf("submitted job array %s: %zu tasks over %zu jobs, script %s\n", id.c_str(),
                slurmShards(o.cluster, m.jobs.size()), m.jobs.size(), script.c_str());
    std::fflush(stdout);
    if (!o.wait) return;
    waitForSlurmJob(id);
    return reportMerge(m, true);
  }
  // This shard's jobs: index % N == I, in manifest order (every machine expands the same list).
  std::vector<Job> jobs = m.jobs;
  std::string stem = (m.outDir / "results").string();
  if (!o.shard.empty()) {
    const auto [i, n] = parseShard(o.shard);
    jobs = shardJobs(jobs, i, n);
    stem += "-shard-" + std::to_string(i) + "-of-" + std::to_string(n);
  }
  if (o.dryRun) {
    for (const Job& j : jobs) std::printf("%s %s\n", j.name.c_str(), j.spec.dump().c_str());
    return;
  }
  const BatchReport r =
      runJobs(jobs, m.outDir, stem, o.batch,
              {{"manifest", m.path}, {"shard", o.shard.empty() ? "0/1" : o.shard},
               {"jobs_in_flight", o.batch.jobsInFlight}, {"threads_per_job", o.batch.threadsPerJob}});
  auto count = [&](const char* s) { return r.counts.count(s) ? r.counts.at(s) : size_t(0); };
  std::printf("batch: %zu jobs: %zu ok, %zu existing, %zu failed, %zu interrupted, %zu not run; wrote %s.csv, %s.json\n",
              jobs.size(), count("ok"), count("existing"), count("failed"), count("interrupted"), count("not run"),
              stem.c_str(), stem.c_str());
  if (r.interrupted)
    throw CancelledError("results of the jobs that ran written to " + stem + ".csv; --skip-existing resumes");
  if (count("failed") + count("interrupted") > 0) throw CLI::RuntimeError(1);
}

}  // namespace

void addBatchCommand(CLI::App& app) {
  auto o = std::make_shared<BatchOptions>();
  CLI::App* cmd = app.add_subcommand("batch", "Run the renders of a manifest (jobs and grids of settings) in parallel");
  cmd->add_option("manifest", o->manifestPath, "Manifest (JSON)")->required();
  cmd->add_option("-o,--output", o->outDir, "Output folder")
      ->default_str("the manifest's output_dir, else <manifest>/");
  cmd->add_option("-j,--jobs", o->batch.jobsInFlight, "Jobs in flight; mind memory: each holds its scene and field")
      ->check(CLI::Range(1, 1024));
  cmd->add_option("-t,--threads", o->batch.threadsPerJob, "Threads per job (0 = all)")->check(CLI::Range(0, 4096));
  cmd->add_flag("--skip-existing", o->batch.skipExisting, "Keep jobs whose outputs exist (resume an interrupted batch)");
  cmd->add_option("--shard", o->shard, "Run the jobs whose index % N == I (I/N), for spreading over machines");
  cmd->add_option("--memory-budget-mb", o->batch.memoryBudgetMb, "Heap limit per job; a job over it fails and the batch goes on")
      ->check(positiveNumber())
      ->default_str("none");
  cmd->add_flag("--dry-run", o->dryRun, "Print the expanded jobs (name and settings) and exit");
  cmd->add_flag("-q,--quiet", o->batch.quiet, "No per-job lines");
  cmd->add_flag("--slurm", o->slurm,
                "Submit the manifest to Slurm as a job array (one task per shard, each 'batch --shard I/N "
                "--skip-existing'); the sbatch script is written to OUT/slurm/ and the job id printed");
  cmd->add_option("--shards", o->cluster.shards, "--slurm: array tasks")->check(CLI::Range(1, 1000000))
      ->default_str("one per job");
  cmd->add_option("--partition", o->cluster.partition, "--slurm: the partition to submit to");
  cmd->add_option("--time", o->cluster.timeLimit, "--slurm: each task's time limit (Slurm's format, e.g. 30:00)");
  cmd->add_option("--array-limit", o->cluster.arrayLimit, "--slurm: at most this many tasks running at once")
      ->check(CLI::Range(1, 1000000))
      ->default_str("no limit");
  cmd->add_flag("--wait", o->wait, "--slurm: wait for the array to finish, then --merge");
  cmd->add_flag("--status", o->status, "Which jobs are complete, failed, interrupted or missing (from the outputs "
                                       "and the shards' tables); exit 1 unless all are complete");
  cmd->add_flag("--merge", o->merge, "Join the shards' results into OUT/results.{csv,json} (one row per job of "
                                     "the manifest, in order), naming the jobs missing or failed; exit 1 unless all "
                                     "are complete");
  cmd->callback([o] { runBatch(*o); });
}

}  // namespace voxcone
