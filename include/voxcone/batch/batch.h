#pragma once
/// \file batch.h
/// Batches of renders: a manifest (jobs and grids of settings) expanded into named jobs, each run
/// as a child `voxcone render` process (its own peak RSS, memory budget and crash), in parallel,
/// with a results table (CSV and JSON) of times, memory and errors against references; shards of
/// a manifest for several machines, their tables merged, and Slurm job arrays that run the shards.
/// The CLI (src/cli/cmd_batch.cpp) and the studies are thin layers over this.

#include <nlohmann/json.hpp>

#include <cstddef>
#include <filesystem>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace voxcone {

/// One render of a batch.
struct Job {
  std::string name;     ///< the outputs' name: given, or from the settings (jobName)
  nlohmann::json spec;  ///< scene, method, spp, res, seed, max_depth, options, reference... (paths resolved)
};

/// What a job gave.
struct JobResult {
  /// "ok", "existing" (skipped: its outputs were there), "failed", "interrupted" (stopped by a
  /// signal; no outputs), "not run", "missing" (merge: no shard produced it).
  std::string status;
  std::string error;
  nlohmann::json sidecar;
  nlohmann::json metrics;
};

/// A manifest read and expanded.
struct Manifest {
  std::string path;              ///< absolute
  std::vector<Job> jobs;         ///< in manifest order (every machine expands the same list)
  std::filesystem::path outDir;  ///< the given one, else the manifest's output_dir, else <manifest stem>/ beside it
};

/// Read and expand the manifest at `path` (SettingsError naming the key for anything wrong,
/// a missing reference included, before any job runs). `outDir` overrides its output_dir.
Manifest loadManifest(const std::string& path, const std::string& outDir = "");

/// The jobs of a parsed manifest, in order: "jobs" first, then each "grid" entry expanded (every
/// array value, top level or in options, is an axis; axes in key order, options' at "options",
/// the last varying fastest). Paths are resolved against `base`.
std::vector<Job> expandManifest(const nlohmann::json& manifest, const std::filesystem::path& base);

/// The deterministic output name of a job spec: scene, method, spp and every option, then a
/// hash of the whole spec.
std::string jobName(const nlohmann::json& spec);

/// "I/N" (0 <= I < N) parsed; SettingsError otherwise.
std::pair<size_t, size_t> parseShard(const std::string& shard);
/// Shard i of n: jobs i, i + n, i + 2n, ...
std::vector<Job> shardJobs(const std::vector<Job>& jobs, size_t i, size_t n);

/// How a batch runs its jobs.
struct BatchSettings {
  int jobsInFlight = 1;         ///< renders at once
  int threadsPerJob = 0;        ///< -t of each render (0 = all); a job's "threads" overrides it
  bool skipExisting = false;    ///< keep jobs whose outputs are complete (completeOutputs)
  double memoryBudgetMb = 0.0;  ///< heap limit per render (ulimit -d), 0 none
  bool quiet = false;           ///< no "[i/N] ..." line per finished job on stderr
  std::string executable;       ///< the voxcone to run; "" = this executable
};

/// What runJobs did: one row per job (resultRow), counts per status.
struct BatchReport {
  std::vector<nlohmann::json> rows;
  std::map<std::string, size_t> counts;
  bool interrupted = false;  ///< SIGINT / SIGTERM arrived (installInterruptHandler)
};

/// Run `jobs` into outDir/<name>.{exr,png,json} and write the table stem.{csv,json} (with `info`
/// at its top). SIGINT / SIGTERM: no job starts any more and the running renders get SIGTERM
/// (their status "interrupted", the others "not run"); the table is still written.
BatchReport runJobs(const std::vector<Job>& jobs, const std::filesystem::path& outDir, const std::string& stem,
                    const BatchSettings& settings, const nlohmann::json& info);

/// Whether job `name` left a complete set in `outDir`: its sidecar parses and its EXR opens at
/// the size the sidecar records.
bool completeOutputs(const std::filesystem::path& outDir, const std::string& name);

/// A results-table row: the job's settings, status, error, timings, memory, metrics.
nlohmann::json resultRow(const Job& job, const JobResult& result);
/// Write the table as stem.json (`info` plus "rows") and stem.csv, atomically.
void writeTables(const std::vector<nlohmann::json>& rows, const std::string& stem, const nlohmann::json& info);

/// The manifest's jobs as its shards left them in `outDir`: a job whose outputs are complete is
/// "ok" (its row read again from its sidecar, metrics recomputed), whatever a shard table says (a
/// task killed after a job but before its table was written loses nothing); otherwise the
/// reason from the newest shard table that lists it (failed, interrupted, not run) or "missing".
struct MergeReport {
  std::vector<nlohmann::json> rows;     ///< one per job, in manifest order
  std::map<std::string, size_t> counts;
  std::vector<std::string> notComplete; ///< "NAME: status (why)"
};
MergeReport mergeShards(const std::vector<Job>& jobs, const std::filesystem::path& outDir);

/// A Slurm job array's submission settings.
struct SlurmSettings {
  size_t shards = 0;      ///< array tasks, 0: one per job (at most one per job)
  std::string partition;  ///< "" for the cluster's default
  std::string timeLimit;  ///< per task, Slurm's format; "" for the partition's
  int arrayLimit = 0;     ///< tasks running at once (the %K of --array), 0 none
};

/// The tasks a manifest of `jobs` jobs is cut into.
size_t slurmShards(const SlurmSettings& slurm, size_t jobs);

/// The sbatch script of the manifest's job array: task i runs shard i/N of it with
/// --skip-existing (so a task requeued, or resubmitted alone with sbatch --array=i, runs exactly
/// the jobs it is missing); N written in, not read from SLURM_ARRAY_TASK_COUNT, which a task
/// resubmitted alone would change; logs in outDir/slurm/.
std::string slurmScript(const SlurmSettings& slurm, const BatchSettings& batch, const std::string& manifestPath,
                        const std::filesystem::path& outDir, size_t jobs);

/// The job id in sbatch --parsable's output ("ID" or "ID;CLUSTER"); Error when there is none.
std::string parseSbatchJobId(const std::string& out);

/// Write the script to outDir/slurm/<manifest stem>.sbatch and submit it with sbatch; returns the
/// job id and the script's path. Error (naming sbatch's message) when sbatch is missing or fails.
std::pair<std::string, std::string> submitSlurm(const SlurmSettings& slurm, const BatchSettings& batch,
                                                const std::string& manifestPath,
                                                const std::filesystem::path& outDir, size_t jobs);

/// Until Slurm job `id` has left the queue (every task done, requeued ones included); polls
/// squeue every 2 s. CancelledError on SIGINT / SIGTERM (the array keeps running).
void waitForSlurmJob(const std::string& id);

}  // namespace voxcone
